"""Shared fixtures: small maps built through the bindings themselves."""
import json
import os
import pathlib

import pytest

import dsm

EXAMPLES = pathlib.Path(os.environ.get("DSM_EXAMPLES_DIR", pathlib.Path(__file__).parents[2] / "examples"))

# Two semi-transparent cards over a ground plane, lit by a spot light.
CARDS_SCENE = {
    "light": {"type": "spot", "position": [0, 4, 0], "look_at": [0, 0, 0], "up": [0, 0, -1], "fov": 50,
              "resolution": [64, 64],
              "near": 0.5},
    "objects": [
        {"type": "quad", "center": [0, 2, 0], "u": [0.6, 0, 0], "v": [0, 0, 0.6], "opacity": [0.5, 0.5, 0.5]},
        {"type": "sphere", "center": [0.4, 1.0, 0.3], "radius": 0.4, "opacity": [0.8, 0.8, 0.8]},
        {"type": "plane", "normal": [0, 1, 0], "size": 6.0},
    ],
}


def tool(name):
    """Path of a dsm-* executable of the same build."""
    directory = os.environ.get("DSM_BIN_DIR")
    if not directory:
        pytest.skip("DSM_BIN_DIR not set (run through ctest)")
    return str(pathlib.Path(directory) / name)


@pytest.fixture(scope="session")
def cards_map(tmp_path_factory):
    path = tmp_path_factory.mktemp("maps") / "cards.dsm"
    dsm.build(CARDS_SCENE, path, spp=16, seed=3)
    return path


@pytest.fixture(scope="session")
def leaves_map(tmp_path_factory):
    path = tmp_path_factory.mktemp("maps") / "leaves.dsm"
    dsm.build(EXAMPLES / "leaves.json", path, resolution=48, spp=4)
    return path
