#!/usr/bin/python3
"""Checks the direction of includes between libdsm's components.

Each folder libdsm/<component>/ holds include/dsm/*.h (public) and src/ (the
sources and private headers). A component may include only its own headers and
those of the components it builds on (ALLOWED below); nothing of the library
may include the umbrella headers of libdsm/include/dsm (dsm.h, build.h, ...).

Usage: check_component_includes.py ROOT      check the tree at ROOT
       check_component_includes.py --self-test
Exit status 1 and one line per offending include when the direction is broken.
"""

import pathlib
import re
import sys
import tempfile

CORE_SIDE = {"core", "format", "lookup", "soft", "ops"}
# What each component may include, itself included. dsm::core is the first five.
ALLOWED = {
    "core": {"core"},
    "format": {"core", "format"},
    "lookup": {"core", "format", "lookup"},
    "soft": {"core", "format", "lookup", "soft"},
    "ops": {"core", "format", "lookup", "soft", "ops"},
    "build": CORE_SIDE | {"build"},
    "exr": CORE_SIDE | {"exr"},
    "reference": CORE_SIDE | {"build", "reference"},
    "c": CORE_SIDE | {"c"},
    "farm": CORE_SIDE | {"build", "farm"},
}
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^">]+)[">]')
SOURCES = {".h", ".hpp", ".c", ".cpp"}


def owners(library):
    """Header path as included ("dsm/x.h" or "x.h") -> owning component."""
    public, private = {}, {}
    for component_dir in sorted(p for p in library.iterdir() if p.is_dir()):
        component = component_dir.name
        for header in (component_dir / "include" / "dsm").glob("*.h"):
            public["dsm/" + header.name] = component
        for header in (component_dir / "include").glob("*.h"):  # C headers
            public[header.name] = component
        for header in (component_dir / "src").glob("*.h"):
            private.setdefault(header.name, set()).add(component)
    return public, private


def check(root):
    library = pathlib.Path(root) / "libdsm"
    public, private = owners(library)
    problems = []
    for component_dir in sorted(p for p in library.iterdir() if p.is_dir()):
        component = component_dir.name
        if component == "include":
            continue
        if component not in ALLOWED:
            problems.append(f"libdsm/{component}: a folder that is no known component (add it to ALLOWED)")
            continue
        for source in sorted(component_dir.rglob("*")):
            if source.suffix not in SOURCES:
                continue
            for number, line in enumerate(source.read_text(errors="replace").splitlines(), 1):
                match = INCLUDE.match(line)
                if not match:
                    continue
                name = match.group(1)
                where = f"{source.relative_to(root)}:{number}: {name}"
                if name.startswith("dsm/") and (library / "include" / name).exists():
                    problems.append(f"{where}: an umbrella header; include the component's own headers")
                    continue
                owner = public.get(name)
                if owner is None and "/" not in name:
                    candidates = private.get(name, set())
                    owner = component if component in candidates else min(candidates, default=None)
                if owner is None:
                    if name.startswith("dsm/"):
                        problems.append(f"{where}: no component has this header")
                    continue  # a system or third-party header
                if owner not in ALLOWED[component]:
                    problems.append(f"{where}: {component} may not include {owner} "
                                    f"(allowed: {', '.join(sorted(ALLOWED[component]))})")
    return problems


def self_test():
    """The check passes on a clean tree and fails on each kind of bad include."""

    def tree(files):
        directory = tempfile.TemporaryDirectory()
        for path, text in files.items():
            target = pathlib.Path(directory.name) / path
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text)
        return directory

    clean = {
        "libdsm/include/dsm/dsm.h": '#include "dsm/visibility.h"\n',
        "libdsm/core/include/dsm/visibility.h": "#include <vector>\n",
        "libdsm/core/src/text.h": "",
        "libdsm/core/src/visibility.cpp": '#include "dsm/visibility.h"\n#include "text.h"\n',
        "libdsm/format/include/dsm/reader.h": '#include "dsm/visibility.h"\n',
        "libdsm/format/src/reader_impl.h": '#include "text.h"\n',
        "libdsm/lookup/src/lookup.cpp": '#include "reader_impl.h"\n#include "dsm/reader.h"\n',
    }
    bad = {
        "core including format": ("libdsm/core/src/visibility.cpp", '#include "dsm/reader.h"\n'),
        "core including a private header of format": ("libdsm/core/src/visibility.cpp", '#include "reader_impl.h"\n'),
        "format including lookup": ("libdsm/format/src/reader.cpp", '#include "dsm/lookup.h"\n'),
        "a component including an umbrella header": ("libdsm/format/src/reader.cpp", '#include "dsm/dsm.h"\n'),
        "an unknown dsm header": ("libdsm/core/src/x.cpp", "#include <dsm/nothing.h>\n"),
    }
    clean_with_lookup = dict(clean, **{"libdsm/lookup/include/dsm/lookup.h": '#include "dsm/reader.h"\n'})
    with tree(clean_with_lookup) as directory:
        if check(directory):
            print("self-test: a clean tree fails:", *check(directory), sep="\n  ")
            return 1
    for what, (path, text) in bad.items():
        files = dict(clean_with_lookup)
        files[path] = files.get(path, "") + text
        with tree(files) as directory:
            if not check(directory):
                print(f"self-test: {what} passes the check")
                return 1
    print(f"self-test: a clean tree passes, {len(bad)} bad includes fail")
    return 0


def main(argv):
    if argv[1:] == ["--self-test"]:
        return self_test()
    if len(argv) != 2:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    problems = check(argv[1])
    for problem in problems:
        print(problem)
    if problems:
        return 1
    print("component includes: every include points down or sideways within its component")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
