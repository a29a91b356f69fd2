#!/usr/bin/env python3
"""Where the instructions of a one-thread dsm-build go, by stage, from a
callgrind profile (inclusive counts of the functions that make up each stage).

    valgrind --tool=callgrind --callgrind-out-file=build.cg \\
        build/tools/dsm-build examples/hairball.json -r 128 -s 16 -j 1 -q -o x.dsm
    bench/build_stages.py build.cg 262144        # samples: 128 * 128 * 16

Prints a Markdown table: instructions per sample and share of the build
(buildMap). The stages are those of dsm-build --stats-json: "sampling" is
placing the samples and finding their crossings; "after sampling" is
gathering each pixel's inputs (the filter's weights) + transmittance + sweep +
compression + writing, and its share of the stages (sampling and after) is the
instruction count's side of the time share that bench_build_speed prints. The
sweep includes buffering its output for the compressor. Needs
callgrind_annotate (valgrind) on PATH."""
import re
import subprocess
import sys


def annotate(profile, *options):
    return subprocess.run(["callgrind_annotate", "--inclusive=yes", "--show-percs=no", "--threshold=100",
                           *options, profile], capture_output=True, text=True, check=True).stdout


def number(text):
    return int(text.replace(",", ""))


def largest(flat, name):
    """The inclusive count of a function: the largest of its entries (callgrind
    lists inlined code under the file it comes from as well)."""
    best = 0
    for line in flat.splitlines():
        m = re.match(r"\s*([\d,]+)\s+(.*)", line)
        if m and name in m.group(2):
            best = max(best, number(m.group(1)))
    return best


def called_from(tree, callee, caller):
    """What `callee` costs when called by `caller` (callgrind_annotate --tree=caller)."""
    total, block = 0, []
    for line in tree.splitlines():
        if not line.strip():
            block = []
            continue
        block.append(line)
        m = re.match(r"\s*([\d,]+)\s+\*\s+(.*)", line)
        if m and callee in m.group(2):
            for b in block[:-1]:
                c = re.match(r"\s*([\d,]+)\s+<\s+(.*)", b)
                if c and caller in c.group(2):
                    total += number(c.group(1))
            block = []
    return total


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    profile, samples = sys.argv[1], int(sys.argv[2])
    flat = annotate(profile)
    tree = annotate(profile, "--tree=caller")
    whole = number(re.search(r"([\d,]+)\s+PROGRAM TOTALS", flat).group(1))
    build = largest(flat, "dsm::v0::buildMap(dsm::v0::Scene const&")
    # The sweep of a build's pixels: over prepared inputs (this version;
    # the mip levels' sweeps, through the same call, are part of writing) or
    # over views of the transmittances (before).
    sweep = max(called_from(tree, "Sweeper::sweep(dsm::v0::Span<dsm::v0::SweepInput const* const>, "
                                  "dsm::v0::Span<double const>, int, dsm::v0::SweptVertices&", "PixelBuilder"),
                largest(flat, "Sweeper::sweep(dsm::v0::Span<dsm::v0::VisibilityView const>, "
                              "dsm::v0::Span<double const>, int, dsm::v0::VertexSink&"))
    transmittance = largest(flat, "TransmittanceBuilder::build(") + called_from(tree, "SweepInput::assign(", "buildMap")
    # The scanline sampler's two steps of a tile, lambdas of buildMap named by
    # their parameters: sampling it (placing the samples, the hider's
    # crossings) and building its pixels (which calls the sampling). What
    # building the pixels spends outside its callees is gathering each pixel's
    # inputs: the filter's weights (the exponential inline) and the pointers.
    sample_tile = largest(flat, "{lambda(unsigned int, unsigned int, std::array<unsigned int, 4ul> const&")
    compute_tile = largest(flat, "{lambda(unsigned int, unsigned int, std::vector<dsm::v0::VisibilityFunction")
    pixels = largest(flat, "PixelBuilder::build(dsm::v0::Span<dsm::v0::SweepInput const* const>")
    crossings = sample_tile or largest(flat, "ScanlineHider::tileHits(")
    gathering = max(0, compute_tile - sample_tile - pixels - transmittance)
    stages = [
        ("bucketing primitives into tiles", largest(flat, "ScanlineHider::ScanlineHider(")),
        ("sampling: placing the samples, their crossings", crossings),
        ("gathering each pixel's inputs (filter weights)", gathering),
        ("transmittance (built, and prepared for the sweep)", transmittance),
        ("sweep (filtering, output buffered)", sweep),
        # The level-0 pixels' compression; the mip levels' is part of writing.
        ("compression", called_from(tree, "Compressor::pushValid(float const*, double const*", "PixelBuilder")
         + called_from(tree, "Compressor::finish()", "PixelBuilder")),
        # A tile prepared on a worker and appended on the writer's turn, or
        # written whole by writeTile() (which appends through writePreparedTile()).
        ("writing tiles", largest(flat, "MapWriter::prepareTile(")
         + max(largest(flat, "MapWriter::writeTile("), largest(flat, "MapWriter::writePreparedTile("))
         + largest(flat, "MapWriter::finish()")),
    ]
    after = sum(v for _, v in stages[2:])  # gathering to writing
    print("| stage (inclusive) | per sample | share of the build |")
    print("|---|---:|---:|")
    print(f"| whole process | {whole / samples:,.0f} | |")
    print(f"| the build (`buildMap`) | {build / samples:,.0f} | 100 % |")
    for name, v in stages:
        print(f"| {name} | {v / samples:,.0f} | {100 * v / build:.1f} % |")
    print(f"| **after sampling** (gathering to writing) | {after / samples:,.0f} | **{100 * after / build:.1f} %** |")
    print(f"\nAfter sampling ÷ (sampling + after sampling): **{100 * after / (after + crossings):.1f} %**.")


if __name__ == "__main__":
    main()
