#!/usr/bin/env python3
"""Writes pipes.obj for cloud-and-pipes.json: a few tubes (open cylinders swept
along polylines) that run through and around the noise cloud, like the pipes of
Lokovic & Veach's Fig. 11. Run from this directory: python3 make_pipes.py"""
import math

SIDES = 16


def sub(a, b): return [a[i] - b[i] for i in range(3)]
def add(a, b): return [a[i] + b[i] for i in range(3)]
def mul(a, s): return [x * s for x in a]
def dot(a, b): return sum(a[i] * b[i] for i in range(3))
def cross(a, b): return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
def norm(a): return mul(a, 1.0 / math.sqrt(dot(a, a)))


def arc(centre, start, axis, degrees, steps):
    """Points of a circular arc around `axis` through `centre`, from `start`."""
    axis = norm(axis)
    r = sub(start, centre)
    out = []
    for i in range(steps + 1):
        t = math.radians(degrees) * i / steps
        c, s = math.cos(t), math.sin(t)
        # Rodrigues' rotation of r about axis.
        v = add(add(mul(r, c), mul(cross(axis, r), s)), mul(axis, dot(axis, r) * (1 - c)))
        out.append(add(centre, v))
    return out


def tube(path, radius):
    """Rings of SIDES vertices along `path` (parallel-transport frames) and
    the quads between them, as (vertices, faces) with 0-based indices."""
    verts, faces = [], []
    tangent = norm(sub(path[1], path[0]))
    helper = [0, 1, 0] if abs(tangent[1]) < 0.9 else [1, 0, 0]
    normal = norm(cross(tangent, helper))
    for i, p in enumerate(path):
        if 0 < i < len(path) - 1:
            t = norm(sub(path[i + 1], path[i - 1]))
        else:
            t = norm(sub(path[min(i + 1, len(path) - 1)], path[max(i - 1, 0)]))
        normal = norm(sub(normal, mul(t, dot(normal, t))))  # transport the frame
        binormal = cross(t, normal)
        for k in range(SIDES):
            a = 2 * math.pi * k / SIDES
            verts.append(add(p, add(mul(normal, radius * math.cos(a)), mul(binormal, radius * math.sin(a)))))
    for i in range(len(path) - 1):
        for k in range(SIDES):
            a, b = i * SIDES + k, i * SIDES + (k + 1) % SIDES
            faces.append((a, b, b + SIDES, a + SIDES))
    return verts, faces


def line(p, q, steps):
    return [add(p, mul(sub(q, p), i / steps)) for i in range(steps + 1)]


pipes = {
    # Straight through the middle of the cloud along x.
    "main": (line([-3.5, 1.6, 0.0], [3.5, 1.6, 0.0], 1), 0.12),
    # Higher, along z, partly above the cloud.
    "cross": (line([0.8, 2.3, -3.0], [0.8, 2.3, 3.0], 1), 0.08),
    # Rising diagonally behind.
    "diagonal": (line([-3.0, 0.8, -0.7], [3.0, 2.7, -0.7], 1), 0.1),
}
# Up from the ground, a quarter bend, then along +x through the front of the cloud.
bend = line([-1.4, 0.0, 0.9], [-1.4, 1.0, 0.9], 4)[:-1]
bend += arc([-0.8, 1.0, 0.9], [-1.4, 1.0, 0.9], [0, 0, -1], 90, 8)[:-1]
bend += line([-0.8, 1.6, 0.9], [3.5, 1.6, 0.9], 4)
pipes["bend"] = (bend, 0.1)

lines = ["# pipes.obj: written by make_pipes.py (open tubes, %d sides)" % SIDES]
base = 1
for name, (path, radius) in pipes.items():
    verts, faces = tube(path, radius)
    lines.append("o " + name)
    lines += ["v %.5f %.5f %.5f" % tuple(v) for v in verts]
    lines += ["f " + " ".join(str(base + i) for i in f) for f in faces]
    base += len(verts)
with open("pipes.obj", "w") as out:
    out.write("\n".join(lines) + "\n")
