#!/usr/bin/env python3
"""Builds the hair ball, then plots a depth slice of its visibility and the
number of vertices per pixel, and saves them as one PNG.

    PYTHONPATH=build/python python3 python_bindings_optional/examples/hairball_slice.py \
        [--resolution 256] [--spp 16] [-o hairball.png]
"""
import argparse
import pathlib
import tempfile
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dsm  # noqa: E402

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default=str(EXAMPLES / "hairball.json"))
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("-o", "--output", default="hairball.png")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as work:
        path = pathlib.Path(work) / "hairball.dsm"
        stats = dsm.build(args.scene, path, resolution=args.resolution, spp=args.spp)
        print(f"built {path.name}: {stats['wall_seconds']:.1f} s, {stats['file_bytes'] / 2**20:.1f} MiB")
        m = dsm.open(path)
        w, h = m.width, m.height

        # The slice halfway through the depth range the ball occupies.
        depths = np.concatenate([m.pixel(x, y)["z"] for y in range(0, h, 8) for x in range(0, w, 8)])
        z = float(np.median(depths)) if depths.size else 1.0
        ys, xs = np.mgrid[0:h, 0:w]
        raster = np.column_stack([xs.ravel() + 0.5, ys.ravel() + 0.5, np.full(xs.size, z)])
        start = time.perf_counter()
        visibility = m.lookup(raster, space="raster", level=0).reshape(h, w)
        seconds = time.perf_counter() - start
        print(f"slice at z = {z:.3f}: {raster.shape[0] / seconds:,.0f} lookups/s")

        vertices = np.array([[len(m.pixel(x, y)) for x in range(w)] for y in range(h)])

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    shown = axes[0].imshow(visibility, cmap="gray", vmin=0, vmax=1)
    axes[0].set_title(f"visibility at depth {z:.2f}")
    fig.colorbar(shown, ax=axes[0], fraction=0.046)
    shown = axes[1].imshow(vertices, cmap="viridis")
    axes[1].set_title(f"vertices per pixel (mean {vertices.mean():.2f})")
    fig.colorbar(shown, ax=axes[1], fraction=0.046)
    for a in axes:
        a.set_xticks([])
        a.set_yticks([])
    fig.tight_layout()
    fig.savefig(args.output, dpi=100)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
