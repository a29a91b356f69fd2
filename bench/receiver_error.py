#!/usr/bin/python3
"""What a receiver reads behind a semi-transparent surface: the mean signed
error of shadow lookups against the exact transmittance, for maps built
lossless (-e 0), with the greedy compressor (the default) and with
--centred-compression.

Two scenes of bench_compression_bias: an opacity-0.4 sphere and an opacity-0.4
tilted quad over a ground plane, under a spot light. Receivers are random
points on the ground inside each occluder's shadow and at least MARGIN from
its edge, so that the filtered map has no edge to blur there and the exact
transmittance is 0.6 per surface crossed (0.36 behind the sphere, 0.6 behind
the quad). Each point is looked up with dsm-lookup's defaults (bilinear, the
automatic depth bias); the error of the lossless map is the lookup's own (the
bias, the sphere's contact with the ground), and the compressed maps' errors
are read against it.

Usage: receiver_error.py TOOLS_DIR [--resolution 256] [--spp 16,64]
       [--points 4000] [--work DIR]
TOOLS_DIR holds dsm-build and dsm-lookup. Prints a Markdown table, errors in
units of each build's tolerance (0.25 / sqrt(spp)).
"""
import argparse
import math
import os
import random
import subprocess
import sys
import tempfile

LIGHT = (0.0, 6.0, 0.5)
MARGIN = 0.08  # world units from the shadow's edge (about 5 pixels at 256^2)


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def dot(a, b):
    return sum(a[i] * b[i] for i in range(3))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def sphere_crossings(p):
    """Surfaces of the unit sphere at (0, 1, 0) between p and the light, and
    the distance of that ray from the sphere's silhouette."""
    d = sub(LIGHT, p)
    d = [x / math.sqrt(dot(d, d)) for x in d]
    oc = sub(p, [0.0, 1.0, 0.0])
    along = dot(oc, d)
    axis = math.sqrt(max(0.0, dot(oc, oc) - along * along))
    crosses = axis < 1.0 and along < 0.0
    return (2 if crosses else 0), abs(1.0 - axis)


def quad_crossings(p):
    """Surfaces of the tilted quad between p and the light, and the distance
    of the crossing from the quad's nearest edge."""
    c, u, v = [0.0, 1.5, 0.0], [1.5, 0.0, 0.0], [0.0, 1.0, 1.0]
    n = cross(u, v)
    d = sub(LIGHT, p)
    t = dot(sub(c, p), n) / dot(d, n)
    if not 0.0 < t < 1.0:
        return 0, 1.0
    q = [p[i] + t * d[i] - c[i] for i in range(3)]
    s, r = dot(q, u) / dot(u, u), dot(q, v) / dot(v, v)
    edge = min((1.0 - abs(s)) * math.sqrt(dot(u, u)), (1.0 - abs(r)) * math.sqrt(dot(v, v)))
    return (1 if abs(s) < 1.0 and abs(r) < 1.0 else 0), abs(edge)


SCENES = [
    ("sphere, opacity 0.4", '{"type": "sphere", "center": [0, 1, 0], "radius": 1, "opacity": 0.4}',
     sphere_crossings),
    ("tilted quad, opacity 0.4",
     '{"type": "quad", "opacity": 0.4, "center": [0, 1.5, 0], "u": [1.5, 0, 0], "v": [0, 1, 1]}',
     quad_crossings),
]


def receivers(crossings, count, rng):
    points, truth = [], []
    while len(points) < count:
        p = [rng.uniform(-2.2, 2.2), 0.0, rng.uniform(-2.2, 2.2)]
        k, edge = crossings(p)
        if k == 0 or edge < MARGIN:
            continue
        points.append(p)
        truth.append(0.6 ** k)
    return points, truth


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tools")
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--spp", default="16,64")
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--work", default=None, help="directory for the scenes and maps (default: a temporary one)")
    args = ap.parse_args()
    build, lookup = os.path.join(args.tools, "dsm-build"), os.path.join(args.tools, "dsm-lookup")
    work = args.work or tempfile.mkdtemp(prefix="dsm-receivers-")
    os.makedirs(work, exist_ok=True)
    rng = random.Random(1)
    print(f"{args.resolution}², receivers on the ground inside the shadow; mean signed error of the lookups "
          "(lookup - exact), in units of the tolerance")
    print()
    print("| scene | spp | lossless | greedy | centred | greedy - lossless | centred - lossless |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, occluder, crossings in SCENES:
        scene = os.path.join(work, "scene.json")
        with open(scene, "w") as f:
            f.write('{"light": {"type": "spot", "position": [0, 6, 0.5], "look_at": [0, 0, 0], "fov": 50}, '
                    '"objects": [' + occluder + ', {"type": "plane", "normal": [0, 1, 0], "size": 12}]}')
        points, truth = receivers(crossings, args.points, rng)
        queries = os.path.join(work, "points.txt")
        with open(queries, "w") as f:
            f.writelines(f"{p[0]!r} {p[1]!r} {p[2]!r}\n" for p in points)
        for spp in (int(s) for s in args.spp.split(",")):
            eps = 0.25 / math.sqrt(spp)
            errors = {}
            for mode, extra in (("lossless", ["-e", "0"]), ("greedy", []), ("centred", ["--centred-compression"])):
                out = os.path.join(work, f"{mode}.dsm")
                subprocess.run([build, scene, "-o", out, "-q", "-r", str(args.resolution), "-s", str(spp)] + extra,
                               check=True)
                answers = subprocess.run([lookup, out, "-i", queries], check=True, capture_output=True,
                                         text=True).stdout.split()
                if len(answers) != len(points):
                    sys.exit(f"receiver_error.py: {len(answers)} answers for {len(points)} points")
                errors[mode] = sum(float(a) - t for a, t in zip(answers, truth)) / len(points) / eps
            print(f"| {name} | {spp} | {errors['lossless']:+.3f} | {errors['greedy']:+.3f} | "
                  f"{errors['centred']:+.3f} | {errors['greedy'] - errors['lossless']:+.3f} | "
                  f"{errors['centred'] - errors['lossless']:+.3f} |", flush=True)


if __name__ == "__main__":
    main()
