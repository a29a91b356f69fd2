"""The bindings against the library's own tools: same descriptions, same
answers, errors as dsm.Error."""
import json
import subprocess
import time

import numpy as np
import pytest

import dsm
from conftest import CARDS_SCENE, tool


def test_open_exposes_header_levels_and_camera(cards_map):
    m = dsm.open(cards_map)
    assert (m.width, m.height, m.channels) == (64, 64, 1)
    assert [lv["width"] for lv in m.levels] == [64, 32, 16, 8, 4, 2, 1]
    assert m.levels[0]["tolerance"] == pytest.approx(0.25 / 4)
    assert m.camera["world_to_light"].shape == (4, 4)
    assert m.camera["projection"] == "perspective"
    assert m.metadata["settings"]["spp"] == 16


def test_info_equals_dsm_info_json(cards_map):
    m = dsm.open(cards_map)
    cli = json.loads(subprocess.run([tool("dsm-info"), "--json", str(cards_map)], check=True,
                                    capture_output=True, text=True).stdout)
    assert m.info() == cli


def test_pixel_is_a_structured_array_of_the_function(cards_map):
    m = dsm.open(cards_map)
    v = m.pixel(32, 32)
    assert v.dtype.names == ("z", "v", "count", "layer")
    assert len(v) >= 2
    assert np.all(np.diff(v["z"]) >= 0)
    assert np.all(np.diff(v["v"]) <= 0)
    # The card (opacity 0.5) then the ground: V drops to about 0.5, then to 0.
    assert v["v"][-1] == pytest.approx(0.0, abs=1e-6)
    assert np.any(np.abs(v["v"] - 0.5) < 0.1)


def test_rgb_pixel_has_three_channels(leaves_map):
    m = dsm.open(leaves_map)
    assert m.channels == 3
    values = m.lookup(np.array([[24.0, 24.0, 1e6]]), space="raster")
    assert values.shape == (1, 3)
    found_rgb = False
    for y in range(0, 48, 4):
        for x in range(0, 48, 4):
            v = m.pixel(x, y)
            if v.dtype.names == ("z", "r", "g", "b", "count", "layer"):
                found_rgb = True
    assert found_rgb


def test_lookup_matches_single_point_evaluation_of_the_pixel(cards_map):
    m = dsm.open(cards_map)
    f = m.pixel(10, 20)
    depths = np.linspace(0.0, float(f["z"][-1]) * 1.2 + 1.0, 57)
    points = np.column_stack([np.full_like(depths, 10.5), np.full_like(depths, 20.5), depths])
    got = m.lookup(points, space="raster", filter_width=1.0, filter="box", level=0, bias=0.0)
    expected = np.interp(depths, f["z"].astype(np.float64), f["v"].astype(np.float64), left=1.0)
    # np.interp is left-continuous at steps; compare away from vertex depths.
    away = np.min(np.abs(depths[:, None] - f["z"][None, :]), axis=1) > 1e-4
    assert np.allclose(got[away], expected[away], atol=1e-6)


def test_lookup_error_bounds_and_threads_agree(cards_map):
    m = dsm.open(cards_map)
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.uniform(0, 64, 20000), rng.uniform(0, 64, 20000), rng.uniform(0, 6, 20000)])
    one, b1 = m.lookup(pts, space="raster", filter_width=3.0, error_bound=True, threads=1)
    many, b2 = m.lookup(pts, space="raster", filter_width=3.0, error_bound=True, threads=4)
    assert np.array_equal(one, many) and np.array_equal(b1, b2)
    assert np.all(b1 >= m.levels[0]["tolerance"])


def test_large_batch_equals_lookups_one_point_at_a_time(cards_map):
    m = dsm.open(cards_map)
    rng = np.random.default_rng(14)
    n = 20000
    # World points over the cards and the ground, some outside the light's view.
    pts = np.column_stack([rng.uniform(-4, 4, n), rng.uniform(-0.5, 2.5, n), rng.uniform(-4, 4, n)])
    for options in ({"filter_width": 1.0}, {"filter_width": 5.0, "filter": "gaussian"},
                    {"filter_width": 3.0, "filter": "triangle", "level": 1, "bias": 0.01}):
        batch, bounds = m.lookup(pts, error_bound=True, threads=2, **options)
        single = np.empty(n)
        single_bounds = np.empty(n)
        for i in range(n):
            v, b = m.lookup(pts[i:i + 1], error_bound=True, threads=1, **options)
            single[i], single_bounds[i] = v[0], b[0]
        assert np.array_equal(batch, single), options
        assert np.array_equal(bounds, single_bounds), options
        assert np.any(batch < 0.5) and np.any(batch == 1.0)


def test_cache_stats_count_reads_once_per_tile(cards_map):
    # A private cache smaller than the map: tiles come and go, two threads
    # share it, and no tile is ever read twice at once.
    m = dsm.open(cards_map, cache_mb=0.05)
    rng = np.random.default_rng(3)
    n = 50000
    pts = np.column_stack([rng.uniform(0, 64, n), rng.uniform(0, 64, n), rng.uniform(0, 6, n)])
    m.lookup(pts, space="raster", threads=2)
    stats = m.cache_stats()
    assert stats["duplicate_reads"] == 0
    assert stats["tiles_read"] > 0 and stats["evictions"] > 0
    assert stats["peak_tiles_in_use"] >= stats["tiles_in_use"] >= 1
    assert stats["waits"] >= 0


def test_lookups_of_more_points_than_one_batch(cards_map):
    # More than 2^18 points per thread: looked up in several batches.
    m = dsm.open(cards_map)
    rng = np.random.default_rng(18)
    n = 600000
    pts = np.column_stack([rng.uniform(-2, 66, n), rng.uniform(-2, 66, n), rng.uniform(0, 6, n)])
    whole, bounds = m.lookup(pts, space="raster", filter_width=2.0, error_bound=True, threads=1)
    step = 7919
    parts = [m.lookup(pts[i:i + step], space="raster", filter_width=2.0, error_bound=True, threads=1)
             for i in range(0, n, step)]
    assert np.array_equal(whole, np.concatenate([v for v, _ in parts]))
    assert np.array_equal(bounds, np.concatenate([b for _, b in parts]))
    pts[590000] = (1.0, 2.0, np.inf)
    with pytest.raises(dsm.Error, match="lookup: point 1,2 at depth inf is not finite"):
        m.lookup(pts, space="raster", threads=1)


def test_lookup_failure_in_a_batch_raises_dsm_error(cards_map):
    m = dsm.open(cards_map)
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(0, 64, 20000), rng.uniform(0, 64, 20000), rng.uniform(0, 6, 20000)])
    pts[15000] = (np.nan, 1.0, 1.0)
    for threads in (1, 2):
        with pytest.raises(dsm.Error, match="lookup: point nan,1 at depth 1 is not finite"):
            m.lookup(pts, space="raster", threads=threads)
    with pytest.raises(dsm.Error, match="filter width -1 is not a finite value >= 0"):
        m.lookup(pts[:10], space="raster", filter_width=-1.0)
    # The map stays usable after a failed batch.
    assert m.lookup(pts[:10], space="raster").shape == (10,)


def test_errors_raise_dsm_error(tmp_path, cards_map):
    with pytest.raises(dsm.Error, match="missing.dsm"):
        dsm.open(tmp_path / "missing.dsm")
    bad = tmp_path / "bad.dsm"
    bad.write_bytes(b"not a map at all")
    with pytest.raises(dsm.Error, match="bad.dsm"):
        dsm.open(bad)
    m = dsm.open(cards_map)
    with pytest.raises(dsm.Error):
        m.pixel(64, 0)
    with pytest.raises(ValueError):
        m.lookup(np.zeros((3, 2)))
    with pytest.raises(ValueError):
        m.lookup(np.zeros((3, 3)), space="screen")
    with pytest.raises(TypeError):
        dsm.build(CARDS_SCENE, tmp_path / "x.dsm", samples=4)
    with pytest.raises(dsm.Error):
        dsm.build({"light": {"type": "spot", "up": [0, 0, 1]}, "objects": [{"type": "teapot"}]}, tmp_path / "y.dsm")
    assert not (tmp_path / "y.dsm").exists()


def test_build_returns_statistics_and_validates(tmp_path):
    out = tmp_path / "b.dsm"
    stats = dsm.build(CARDS_SCENE, out, resolution=(32, 16), spp=4, mip_levels=1)
    assert stats["pixels"] == 32 * 16 and stats["file_bytes"] == out.stat().st_size
    dsm.validate(out)
    assert len(dsm.open(out).levels) == 1


def test_example_script_writes_a_png(tmp_path):
    import os
    import pathlib
    import sys
    script = pathlib.Path(__file__).parents[1] / "examples" / "hairball_slice.py"
    out = tmp_path / "hairball.png"
    env = dict(os.environ)
    subprocess.run([sys.executable, str(script), "--resolution", "32", "--spp", "1", "-o", str(out)], check=True,
                   env=env, capture_output=True)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bias_is_automatic_unless_a_number_is_given(cards_map):
    m = dsm.open(cards_map)
    f = m.pixel(10, 20)
    z = float(f["z"][0])  # the first surface's own depth: half shadowed without a bias
    point = np.array([[10.5, 20.5, z]])
    automatic = m.lookup(point, space="raster", level=0)
    assert np.array_equal(automatic, m.lookup(point, space="raster", level=0, bias="auto"))
    assert np.array_equal(m.lookup(point, space="raster", level=0, bias=z),
                          m.lookup(np.array([[10.5, 20.5, 0.0]]), space="raster", level=0, bias=0.0))
    # The automatic bias is larger than none: the point reads at least as lit.
    assert np.all(automatic >= m.lookup(point, space="raster", level=0, bias=0.0))
    with pytest.raises(ValueError):
        m.lookup(point, space="raster", bias="sometimes")
