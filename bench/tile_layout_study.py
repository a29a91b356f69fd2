#!/usr/bin/python3
"""Bytes of alternative depth codings of a coded map's tiles (a study behind spec/dsm-format.md §7).

Reads every pixel of the first LEVELS levels with spec/dsm_reader.py, re-encodes each tile with the
1.1 layout but the depths coded as each variant says, deflates the parts in blocks of their own (as the
writer does, at zlib level ZLEVEL) and prints the total per variant. Pure Python: minutes per variant
on a 512² map.

    bench/tile_layout_study.py MAP [LEVELS [VARIANT,... [ZLEVEL]]]

Variants (the anchor is a pixel's first depth; "ends" are its first and last, the steps in between):
    base            first from the previous non-empty pixel's first, then steps to the last
    firstMED        first predicted by the median (LOCO-I) of the left, upper and upper-left firsts
    lastMED         last predicted by that median of the lasts, steps downwards from it
    lastGrad_sep    last by left + upper - upper-left; anchors in a part of their own (_sep)
    last_left_sep   last from the left pixel's last
    both_sep        ends, each by the median predictor; steps in between
    both_left_sep   ends, each from the previous non-empty pixel's (the 1.1 layout)
    both_left_ext_sep  the last coded as last - first, from the previous pixel's
"""
import sys, zlib
import os
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'spec'))
import dsm_reader as R
import numpy as np
M = 0xFFFFFFFF
def varints(vals, out):
    for v in vals:
        v = int(v) & M
        while v >= 0x80:
            out.append((v & 0x7f) | 0x80); v >>= 7
        out.append(v)
def zz(d):
    d &= M
    s = d - (1 << 32) if d >= 0x80000000 else d
    return ((s << 1) ^ (s >> 31)) & M
def med(a, b, c):
    if c >= max(a, b): return min(a, b)
    if c <= min(a, b): return max(a, b)
    return a + b - c
LEVEL = int(sys.argv[4]) if len(sys.argv) > 4 else 6
def deflate_parts(parts, level=None):
    level = level or LEVEL
    c = zlib.compressobj(level)
    out = b''
    for i, p in enumerate(parts):
        out += c.compress(bytes(p))
        out += c.flush(zlib.Z_FINISH if i == len(parts) - 1 else zlib.Z_BLOCK)
    return len(out)

h, levels, pixels = R.read_map(sys.argv[1])
nlev = int(sys.argv[2]) if len(sys.argv) > 2 else len(levels)
ts = h.tile_size
variants = sys.argv[3].split(',') if len(sys.argv) > 3 else ['base', 'firstMED', 'lastMED', 'lastMED_sep', 'lastGrad_sep', 'firstMED_sep', 'last_left_sep', 'both_sep', 'both', 'both_ext_sep', 'both_left_sep', 'both_left_ext_sep']
tot = {v: 0 for v in variants}
parts_tot = {}
for l in range(nlev):
    L = levels[l]; grid = pixels[l]
    for t, tile in enumerate(L.tiles):
        if tile[1] == 0: continue
        tx, ty = t % L.tiles_x, t // L.tiles_x
        w = min(ts, L.width - tx*ts); hh = min(ts, L.height - ty*ts)
        pix = [grid.get((tx*ts + p % w, ty*ts + p // w)) for p in range(w*hh)]
        head = bytearray(); varints([0 if q is None else len(q[2]) for q in pix], head)
        head += bytes([0 if q is None or q[0] == 1 else 1 for q in pix])
        head += bytes([1 if q is None else len(q[1]) + 1 for q in pix])
        for q in pix:
            if q is not None and len(q[1]): 
                st = [0] + [int(s) for s in q[1]]
                varints(np.diff(st), head)
        # values part: recompute as base
        step = L.value_step
        one = 0x3F800000 if step == 0 else int(round(1/step))
        vals = bytearray()
        for q in pix:
            if q is None: continue
            c, st, z, v = q[0], q[1], q[2], q[3]
            k = len(z)
            vf = v.view(np.float32).reshape(k, c)
            keys = (vf.astype(np.float64) / step).round().astype(np.int64) if step else v.reshape(k, c).astype(np.int64)
            bounds = set(int(s) for s in st)
            prev = [one]*c
            d = []
            for i in range(k):
                if i in bounds: prev = [one]*c
                for ch in range(c):
                    d.append((prev[ch] - int(keys[i, ch])) & M); prev[ch] = int(keys[i, ch])
            varints(d, vals)
        counts = bytearray()
        if h.required & 1:
            for q in pix:
                if q is not None: varints(q[4], counts)
        firsts = {p: int(q[2][0]) for p, q in enumerate(pix) if q is not None}
        lasts = {p: int(q[2][-1]) for p, q in enumerate(pix) if q is not None}
        extents = {p: int(q[2][-1]) - int(q[2][0]) for p, q in enumerate(pix) if q is not None}
        def predict(anchors, p, prev, mode):
            x, y = p % w, p // w
            a = anchors.get(p-1) if x > 0 else None
            b = anchors.get(p-w) if y > 0 else None
            c = anchors.get(p-w-1) if x > 0 and y > 0 else None
            if mode == 'left':
                return a if a is not None else prev
            if mode == 'prev':
                return prev
            if a is not None and b is not None and c is not None:
                return med(a, b, c) if mode == 'med' else (a + b - c) & M
            if a is not None: return a
            if b is not None: return b
            return prev
        for var in variants:
            anch = bytearray(); diffs = bytearray(); inter = bytearray()
            prev = 0; lastprev = [0]
            for p, q in enumerate(pix):
                if q is None: continue
                z = q[2].astype(np.int64)
                if var == 'base':
                    inter_vals = [zz(int(z[0]) - prev)] + list(np.diff(z))
                    varints(inter_vals, inter); prev = int(z[0]); continue
                if var.startswith('both'):
                    mode = 'left' if 'left' in var else ('prev' if 'prev' in var else 'med')
                    pr = predict(firsts, p, prev, 'prev' if 'fprev' in var else mode); prev = int(z[0])
                    a = [zz(int(z[0]) - pr)]
                    if len(z) >= 2:
                        if 'ext' in var:
                            a.append(zz((int(z[-1]) - int(z[0])) - predict(extents, p, lastprev[0], mode))); lastprev[0] = int(z[-1]) - int(z[0])
                        else:
                            a.append(zz(int(z[-1]) - predict(lasts, p, lastprev[0], mode))); lastprev[0] = int(z[-1])
                    d = list(np.diff(z[:-1]))
                    if var.endswith('_sep'):
                        varints(a, anch); varints(d, diffs)
                    else:
                        varints(a + d, inter)
                    continue
                if var.startswith('first'):
                    pr = predict(firsts, p, prev, 'med'); prev = int(z[0])
                    a = zz(int(z[0]) - pr); d = list(np.diff(z))
                else:
                    mode = 'med' if 'MED' in var else ('left' if 'left' in var else 'grad')
                    pr = predict(lasts, p, prev, mode); prev = int(z[-1])
                    a = zz(int(z[-1]) - pr); d = list(np.diff(z))[::-1]
                if var.endswith('_sep'):
                    varints([a], anch); varints(d, diffs)
                else:
                    varints([a] + d, inter)
            if var.endswith('_sep'):
                parts = [head + anch, diffs, vals] + ([counts] if counts else [])
            else:
                parts = [head, inter, vals] + ([counts] if counts else [])
            n = deflate_parts(parts)
            raw = sum(len(x) for x in parts)
            tot[var] += min(n, raw)
print({k: v for k, v in tot.items()})
