#!/usr/bin/python3
"""Reads every map the test suite wrote with both readers and compares them.

    check_every_map.py --format-maps EXE --reader spec/dsm_reader.py [--min N] DIR...

Every *.dsm under the directories (the tool checks' work directories, and the
archive the unit tests fill when DSM_TEST_MAP_ARCHIVE is set, see
tests/support/temp_dir.cpp) is read by libdsm (`format_maps dump`) and by the
independent reader written from the spec. A map both read must give the same
dump, every pixel of every level bit for bit; a map libdsm rejects (the
corruption tests write many) must be rejected by the independent reader too,
and the other way round. Maps with the same bytes are read once. Any
disagreement fails, naming the map; the spec decides which reader is wrong.
"""

import argparse
import concurrent.futures
import hashlib
import importlib.util
import io
import os
import subprocess
import sys


_readers = {}


def load_reader(path):
    """The independent reader as a module, loaded once per worker process."""
    if path not in _readers:
        spec = importlib.util.spec_from_file_location("dsm_reader", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        _readers[path] = module
    return _readers[path]


def collect(directories):
    """Unique maps by content: {sha256: first path}."""
    maps = {}
    for directory in directories:
        for root, _, names in os.walk(directory):
            for name in sorted(names):
                if not name.endswith(".dsm"):
                    continue
                path = os.path.join(root, name)
                if not os.path.isfile(path):
                    continue  # the tool checks leave FIFOs and directories named *.dsm
                try:
                    with open(path, "rb") as f:
                        digest = hashlib.sha256(f.read()).hexdigest()
                except OSError:
                    continue  # removed by a test running beside this check
                maps.setdefault(digest, path)
    return maps


def compare(format_maps, reader_path, path):
    """(verdict, detail): verdict is 'same', 'rejected' or 'differ'."""
    libdsm = subprocess.run([format_maps, "dump", path], capture_output=True, text=True, timeout=120)
    reader = load_reader(reader_path)
    out = io.StringIO()
    try:
        reader.dump(path, out)
        independent_error = None
    except Exception as e:  # any failure of the independent reader is a rejection
        independent_error = "%s: %s" % (type(e).__name__, e)
    if libdsm.returncode != 0 and independent_error is not None:
        return "rejected", ""
    if libdsm.returncode != 0:
        return "differ", "libdsm rejects it (%s) but the independent reader reads it" % libdsm.stderr.strip()
    if independent_error is not None:
        return "differ", "libdsm reads it but the independent reader rejects it (%s)" % independent_error
    if libdsm.stdout != out.getvalue():
        ours, theirs = libdsm.stdout.splitlines(), out.getvalue().splitlines()
        for i, (a, b) in enumerate(zip(ours, theirs)):
            if a != b:
                return "differ", "first difference on line %d:\n  libdsm:      %s\n  independent: %s" % (
                    i + 1, a[:200], b[:200])
        return "differ", "dumps differ in length: libdsm %d lines, independent %d" % (len(ours), len(theirs))
    return "same", ""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--format-maps", required=True)
    parser.add_argument("--reader", required=True)
    parser.add_argument("--min", type=int, default=1, help="fail when fewer distinct maps are found")
    parser.add_argument("directories", nargs="+")
    args = parser.parse_args()

    maps = collect(args.directories)
    if len(maps) < args.min:
        print("only %d distinct maps found under %s (expected at least %d)" % (
            len(maps), ", ".join(args.directories), args.min))
        return 1
    verdicts = {"same": 0, "rejected": 0, "differ": 0}
    failures = []
    with concurrent.futures.ProcessPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        futures = {pool.submit(compare, args.format_maps, args.reader, path): path for path in maps.values()}
        for future in concurrent.futures.as_completed(futures):
            verdict, detail = future.result()
            verdicts[verdict] += 1
            if verdict == "differ":
                failures.append("%s: %s" % (futures[future], detail))
    for failure in sorted(failures):
        print("DISAGREE " + failure)
    print("%d distinct maps: %d read identically by both readers, %d rejected by both, %d disagreements" % (
        len(maps), verdicts["same"], verdicts["rejected"], verdicts["differ"]))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
