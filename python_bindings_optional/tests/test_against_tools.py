"""The bindings give the same answers as the command-line tools, in the same
speed class."""
import json
import subprocess
import time

import numpy as np
import pytest

import dsm
from conftest import tool


def test_pixel_equals_dsm_info_pixel(leaves_map):
    m = dsm.open(leaves_map)
    for x, y in [(24, 24), (10, 30), (0, 0), (47, 47)]:
        cli = json.loads(subprocess.run([tool("dsm-info"), str(leaves_map), "--pixel", f"{x},{y}", "--json"],
                                        check=True, capture_output=True, text=True).stdout)["pixel"]
        v = m.pixel(x, y)
        assert len(v) == len(cli["vertices"])
        for row, want in zip(v, cli["vertices"]):
            assert row["z"] == pytest.approx(want["z"], abs=0)
            values = [row[c] for c in ("r", "g", "b")] if "r" in v.dtype.names else [row["v"]]
            got_values = want["value"] if isinstance(want["value"], list) else [want["value"]]
            assert values == pytest.approx(got_values, abs=0)
            assert row["layer"] == want["layer"]


@pytest.mark.parametrize("space,filt,width,level", [("raster", "box", 1.0, "0"), ("world", "gaussian", 3.0, "auto"),
                                                    ("light", "triangle", 6.0, "1")])
def test_lookups_equal_dsm_lookup(cards_map, space, filt, width, level):
    m = dsm.open(cards_map)
    rng = np.random.default_rng(9)
    if space == "raster":
        pts = np.column_stack([rng.uniform(0, 64, 2000), rng.uniform(0, 64, 2000), rng.uniform(0, 6, 2000)])
    elif space == "light":
        # Inside the light's frustum (half-angle 25 degrees), at depths 1..6.
        z = rng.uniform(1, 6, 2000)
        pts = np.column_stack([rng.uniform(-0.45, 0.45, 2000) * z, rng.uniform(-0.45, 0.45, 2000) * z, z])
    else:
        pts = np.column_stack([rng.uniform(-2, 2, 2000), rng.uniform(-0.2, 2.5, 2000), rng.uniform(-2, 2, 2000)])
    lvl = "auto" if level == "auto" else int(level)
    got = m.lookup(pts, space=space, filter=filt, filter_width=width, level=lvl)
    text = "\n".join(f"{x!r} {y!r} {z!r}" for x, y, z in pts) + "\n"
    out = subprocess.run([tool("dsm-lookup"), str(cards_map), "--space", space, "--filter", filt,
                          "--filter-width", str(width), "--level", level], input=text, check=True,
                         capture_output=True, text=True).stdout
    cli = np.array([float(line) for line in out.split()])
    assert cli.shape == got.shape
    # The tool prints 9 significant digits.
    assert np.allclose(got, cli, rtol=0, atol=1e-8)
    assert np.any((got > 0.01) & (got < 0.99)), "the points should meet some shadow"


def test_a_million_lookups_run_in_the_cpp_speed_class(cards_map, capsys):
    m = dsm.open(cards_map)
    rng = np.random.default_rng(1)
    n = 1_000_000
    pts = np.column_stack([rng.uniform(0, 64, n), rng.uniform(0, 64, n), rng.uniform(0, 6, n)])
    start = time.perf_counter()
    values = m.lookup(pts, space="raster")
    python_rate = n / (time.perf_counter() - start)
    assert values.shape == (n,) and np.all((values >= 0) & (values <= 1))
    # The same points through the tool (one thread, text in and out).
    few = pts[:100_000]
    text = "\n".join(f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in few) + "\n"
    start = time.perf_counter()
    subprocess.run([tool("dsm-lookup"), str(cards_map), "--space", "raster"], input=text, check=True,
                   capture_output=True, text=True)
    cli_rate = len(few) / (time.perf_counter() - start)
    with capsys.disabled():
        print(f"\n  lookups: Python bindings {python_rate:,.0f} points/s (all cores); "
              f"dsm-lookup {cli_rate:,.0f} points/s (one thread, text I/O)")
