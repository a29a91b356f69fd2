"""Area-light soft shadows through the bindings."""
import numpy as np
import pytest

import dsm

SQUARE_SCENE = {
    "light": {"type": "spot", "position": [0, 10, 0], "direction": [0, -1, 0], "up": [0, 0, 1], "fov": 60,
              "resolution": 64, "area_radius": 1.0},
    "objects": [
        {"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "size": 40},
        {"type": "quad", "center": [0, 5, 0], "u": [1, 0, 0], "v": [0, 0, 1]},
    ],
}


@pytest.fixture(scope="module")
def square_map(tmp_path_factory):
    path = tmp_path_factory.mktemp("soft") / "square.dsm"
    dsm.build(SQUARE_SCENE, path, spp=16, mtsm_layers=2, tolerance=0.01)
    return dsm.open(path)


def receivers():
    # Under the middle (umbra), across the penumbra, and far outside.
    xs = np.array([0.0, 1.5, 2.0, 2.5, 6.0])
    return np.column_stack([xs, np.full_like(xs, 1e-3), np.zeros_like(xs)])


def test_umbra_penumbra_and_lit(square_map):
    v = square_map.soft_shadow(receivers(), light="disk:1", samples=256, bias=0.05)
    assert v[0] < 0.02
    assert 0.05 < v[2] < 0.95
    assert v[0] <= v[1] <= v[2] <= v[3] <= v[4]
    assert v[4] == 1.0


def test_pcf_baseline_differs_in_the_penumbra_and_agrees_outside(square_map):
    mtsm = square_map.soft_shadow(receivers(), light="disk:1", samples=64, bias=0.05)
    pcf = square_map.soft_shadow(receivers(), light="disk:1", samples=64, bias=0.05, method="pcf")
    assert pcf[4] == mtsm[4] == 1.0
    assert not np.allclose(pcf[1:4], mtsm[1:4])


def test_deterministic_whatever_the_threads(square_map):
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(-3, 3, 3000), np.full(3000, 1e-3), rng.uniform(-3, 3, 3000)])
    a = square_map.soft_shadow(pts, light="rect:2,1", samples=16, bias=0.05, threads=1)
    b = square_map.soft_shadow(pts, light="rect:2,1", samples=16, bias=0.05, threads=3)
    assert np.array_equal(a, b)
    assert np.any((a > 0) & (a < 1))


def test_bad_lights_are_errors(square_map):
    with pytest.raises(ValueError):
        square_map.soft_shadow(receivers(), light="sphere:1")
    with pytest.raises(ValueError):
        square_map.soft_shadow(receivers(), light="disk:x")
    with pytest.raises(ValueError):
        square_map.soft_shadow(receivers(), light="disk:1", method="exact")
    with pytest.raises(dsm.Error):
        square_map.soft_shadow(receivers(), light="disk:5")  # larger than the map was built for


def test_automatic_bias_by_default_and_with_normals(square_map):
    pts = receivers()
    automatic = square_map.soft_shadow(pts, light="disk:1", samples=64)
    assert np.array_equal(automatic, square_map.soft_shadow(pts, light="disk:1", samples=64, bias="auto"))
    assert automatic[0] < 0.05 and automatic[-1] == 1.0  # the umbra stays dark, the lit ground lit
    up = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    with_normals = square_map.soft_shadow(pts, light="disk:1", samples=64, normals=up)
    assert with_normals[0] < 0.05 and with_normals[-1] == 1.0
    with pytest.raises(ValueError):
        square_map.soft_shadow(pts, light="disk:1", normals=up[:2])
    with pytest.raises(ValueError):
        square_map.soft_shadow(pts, light="disk:1", bias="never")


def built(path, **options):
    dsm.build(SQUARE_SCENE, path, resolution=16, spp=4, threads=2, **options)
    return dsm.open(path)


def test_a_scene_with_an_area_light_gets_the_soft_shadow_build_defaults(tmp_path):
    defaults = built(tmp_path / "defaults.dsm")
    settings = defaults.metadata["settings"]
    assert (defaults.max_layers, defaults.has_counts) == (2, True)
    assert (settings["filter"], settings["filter_width"], settings["tolerance"]) == ("box", 1.0, 0.0625)
    # "auto" is the same as leaving an option out; a value given is kept.
    auto = built(tmp_path / "auto.dsm", filter="auto", filter_width="auto", mtsm_layers="auto", tolerance="auto")
    assert auto.metadata["settings"] == settings
    given = built(tmp_path / "given.dsm", filter="gaussian", mtsm_layers=1, tolerance=0.25)
    assert (given.max_layers, given.has_counts) == (1, False)
    assert (given.metadata["settings"]["filter"], given.metadata["settings"]["filter_width"]) == ("gaussian", 2.0)
    assert given.metadata["settings"]["tolerance"] == 0.25
