"""libdsm from Python: open, inspect, look up and build deep shadow maps.

A thin layer over the C++ library (no logic of its own): every answer is the
library's. Errors from the library raise :class:`dsm.Error` with its message,
which names the file, level, tile, pixel or line.

>>> import dsm, numpy as np
>>> m = dsm.open("hairball.dsm")
>>> m.width, m.height, m.channels
>>> m.lookup(np.array([[0.0, 0.0, 0.0]]), space="world")
"""
from __future__ import annotations

import builtins
import json
import os
from typing import Any, Mapping, Sequence, Union

import numpy as np

from . import _dsm
from ._dsm import Error

__all__ = ["Error", "Map", "open", "build", "validate"]


class Map:
    """An open deep shadow map (see :func:`open`). Thread-safe; lookups run on
    all cores with the GIL released."""

    def __init__(self, path: str, cache_mb: float | None = None):
        self._map = _dsm.Map(os.fspath(path), -1.0 if cache_mb is None else float(cache_mb))

    @property
    def path(self) -> str:
        """The file the map was opened from."""
        return self._map.path

    @property
    def width(self) -> int:
        """Width of level 0 in pixels."""
        return self._map.width

    @property
    def height(self) -> int:
        """Height of level 0 in pixels."""
        return self._map.height

    @property
    def channels(self) -> int:
        """1 (monochrome) or 3 (RGB)."""
        return self._map.channels

    @property
    def tile_size(self) -> int:
        return self._map.tile_size

    @property
    def has_counts(self) -> bool:
        """True when vertices carry sample counts (MTSM)."""
        return self._map.has_counts

    @property
    def max_layers(self) -> int:
        """Most MTSM layers a pixel may have (1 = ordinary deep shadow map)."""
        return self._map.max_layers

    @property
    def levels(self) -> list[dict]:
        """Mip levels, finest first: width, height, tolerance, error_bound,
        vertices, non_empty_pixels, stored_bytes."""
        return self._map.levels

    @property
    def camera(self) -> dict:
        """The light camera: projection, world_to_light (4x4 NumPy array,
        light = M @ (world, 1)), screen_window (xmin, xmax, ymin, ymax),
        near_plane."""
        return self._map.camera

    @property
    def metadata(self) -> Any:
        """The metadata: a dict when it is JSON, else the text."""
        text = self._map.metadata_text
        try:
            return json.loads(text)
        except ValueError:
            return text

    def info(self) -> dict:
        """The same description as ``dsm-info --json`` prints."""
        return json.loads(self._map.info_json())

    def pixel(self, x: int, y: int, level: int = 0) -> np.ndarray:
        """The vertices of pixel (x, y) of a level as a structured array with
        fields z, v (or r, g, b for an RGB pixel), count and layer."""
        return self._map.pixel(int(x), int(y), int(level))

    def lookup(self, points, space: str = "world", filter_width: float = 1.0, filter: str = "box",
               level: Union[str, int] = "auto", bias: Union[str, float] = "auto", error_bound: bool = False,
               threads: int = 0):
        """Filtered visibility at each row (x, y, z) of an (N, 3) array.

        space: "world", "light" or "raster" (level-0 pixels, light depth).
        filter_width: in level-0 pixels; filter: "box", "triangle", "gaussian";
        level: "auto" (trilinear mip-mapping) or a level number; bias is
        subtracted from the depth: "auto" (a map pixel's depth footprint at
        the point's depth, dsm/auto_bias.h) or a number. Returns an (N,) array for a monochrome map,
        (N, 3) for RGB; with error_bound=True a tuple (values, bounds).
        threads: 0 = all cores; more than the cores are clamped to them. Each
        thread looks up its share of the points in one batch (tile by tile,
        answers identical to single lookups); a point that cannot be looked
        up raises Error with the reason.
        """
        values, bounds = self._map.lookup(np.asarray(points, dtype=np.float64), space, filter, float(filter_width),
                                          level, bias if isinstance(bias, str) else float(bias), int(threads))
        return (values, bounds) if error_bound else values

    def soft_shadow(self, points, light: str, samples: int = 64, layers: int = 0, bias: Union[str, float] = "auto",
                    z_threshold: float = 0.0, seed: int = 1, method: str = "mtsm", normals=None, threads: int = 0):
        """Fraction of an area light visible from each world point of an
        (N, 3) array, like ``dsm-lookup --area-light``.

        light: "disk:R" (radius) or "rect:W,H" (full sizes), centred on the
        map's light where its build put it (the map should be built from a
        scene whose light has an area_radius: 2 layers by default). method: "mtsm" traces
        `samples` rays per point through the map as a multilayer transparent
        shadow map (layers K: 0 = all; z_threshold and bias in light depth
        units); "pcf" is the classic filtered-lookup baseline. bias: "auto"
        (z_threshold plus a map pixel's depth footprint at the receiver,
        slope-scaled by the receiver's world normal, a row of the (N, 3)
        array `normals`, when given) or a number >= 0. Returns (N,) or
        (N, 3) like lookup(). Deterministic for a seed.
        """
        return self._map.soft_shadow(np.asarray(points, dtype=np.float64), str(light), int(samples), int(layers),
                                     bias if isinstance(bias, str) else float(bias), float(z_threshold), int(seed),
                                     str(method),
                                     None if normals is None else np.asarray(normals, dtype=np.float64),
                                     int(threads))

    def cache_stats(self) -> dict:
        """Counters of the tile cache this map reads through."""
        return self._map.cache_stats()

    def __repr__(self) -> str:
        return f"<dsm.Map '{self.path}' {self.width}x{self.height} channels={self.channels} levels={len(self.levels)}>"


def open(path, cache_mb: float | None = None) -> Map:  # noqa: A001 - mirrors the built-in on purpose
    """Opens a .dsm file. cache_mb: a private tile cache of that many MiB
    (default: the process-wide 256 MiB cache)."""
    return Map(path, cache_mb)


def build(scene: Union[str, os.PathLike, Mapping[str, Any]], out_path, **options) -> dict:
    """Renders a scene from its light into a map, like ``dsm-build``.

    scene: a scene file path or a dict in the scene format (spec/scene.md).
    options: the options of dsm-build with underscores: resolution (N or
    (W, H)), spp, tolerance ("auto" or a number), filter, filter_width,
    mip_levels ("auto" or N), tile_size, mtsm_layers, counts,
    centred_compression, region ((x0, y0, x1, y1)), threads, seed,
    zlib_level. tolerance, filter,
    filter_width and mtsm_layers left out (or "auto") take the scene's
    defaults: those of a map for soft shadows when the light has an
    area_radius (dsm-build's documentation).
    Returns the build statistics as a dict.
    """
    if isinstance(scene, Mapping):
        text, base, name = json.dumps(scene), os.getcwd(), "<dict>"
    else:
        path = os.fspath(scene)
        try:
            with builtins.open(path, "r", encoding="utf-8") as f:
                text = f.read()
        except OSError as e:
            raise Error(f"'{path}': cannot open: {e.strerror}") from None
        base, name = os.path.dirname(os.path.abspath(path)), path
    return _dsm.build(text, base, name, os.fspath(out_path), dict(options))


def validate(path) -> None:
    """Checks every tile of a file (as ``dsm-info --verify``); raises Error."""
    _dsm.validate(os.fspath(path))

