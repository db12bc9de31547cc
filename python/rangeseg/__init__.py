"""rangeseg: segment depth (range) images into planar surfaces and the edges between them.

Belloum, Bouzenada & Mazouzi (2024): multi-seed region growing (region borders C1), Canny on the per-pixel
plane parameters (edges C2) and a simulated-annealing relaxation that reconciles them. The work is done by
the Rust library the ``rangeseg`` command-line tool is built from, with the same results bit for bit.

>>> depth, camera = rangeseg.read("frame.png")          # float32 metres (NaN = no data) and its camera
>>> result = rangeseg.segment(depth, camera)
>>> result.labels.shape, result.planes["normal"][0], result.planes["d"][0]
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Union

import numpy as np

from ._rangeseg import (
    ABW,
    Config,
    ConfigError,
    Grid,
    Pinhole,
    RangesegError,
    ReadError,
    parse_camera,
    read,
    read_bytes,
)
from ._rangeseg import Segmenter as _Segmenter
from ._rangeseg import segment as _segment

__all__ = [
    "ABW",
    "Config",
    "ConfigError",
    "Grid",
    "PLANE_DTYPE",
    "Pinhole",
    "RangesegError",
    "ReadError",
    "Result",
    "Segmenter",
    "load_config",
    "parse_camera",
    "read",
    "read_bytes",
    "segment",
]

Camera = Union[Pinhole, ABW, Grid]
ConfigLike = Union[None, Config, str, "os.PathLike[str]", Mapping[str, Any]]

#: One row per final region: ``normal · X = d`` in the camera's frame (metres for a metric pinhole camera,
#: the image's own units ``(x, y, value)`` for ``Grid``), the region's centroid, pixel count, RMS
#: point-to-plane distance and inclusive bounding box ``[x_min, y_min, x_max, y_max]``.
PLANE_DTYPE = np.dtype(
    [
        ("label", "<i4"),
        ("normal", "<f8", (3,)),
        ("d", "<f8"),
        ("centroid", "<f8", (3,)),
        ("pixels", "<i8"),
        ("rms", "<f8"),
        ("bbox", "<i4", (4,)),
    ]
)


@dataclass(frozen=True)
class Result:
    """What :func:`segment` returns for one depth image."""

    #: Final segmentation, int32, 0 = no region, regions 1.. (the labels of ``planes``).
    labels: np.ndarray
    #: One row per region, dtype :data:`PLANE_DTYPE`, sorted by label.
    planes: np.ndarray
    #: Final edge map C (bool), after relaxation.
    edges: np.ndarray
    #: Region borders C1 from region growing (bool), as detected (the CLI's ``NAME.c1.png``).
    c1: np.ndarray
    #: Canny edges C2 on the plane parameters (bool), as detected (the CLI's ``NAME.c2.png``).
    c2: np.ndarray
    #: Wall-clock milliseconds per stage: features, regiongrow, vcanny, relax.
    timings: Dict[str, float]


def load_config(config: ConfigLike) -> Config:
    """A :class:`Config` from ``None`` (the defaults), a TOML file path, a dict of the TOML's tables, or a Config.

    Unknown keys and bad values raise :class:`ConfigError` with the message the CLI prints.
    """
    if config is None:
        return Config()
    if isinstance(config, Config):
        return config
    if isinstance(config, (str, os.PathLike)):
        return Config.from_path(os.fspath(config))
    if isinstance(config, Mapping):
        try:
            text = json.dumps(config, allow_nan=False)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"<config dict>: {e}") from None
        return Config.from_json(text)
    raise TypeError(f"config must be None, a path, a dict or a rangeseg.Config, got {type(config).__name__}")


def segment(
    depth: np.ndarray,
    camera: Camera,
    config: ConfigLike = None,
    seed: Optional[int] = None,
    *,
    depth_scale: Optional[float] = None,
) -> Result:
    """Segments one depth image into planar regions and edges; the GIL is released while it runs.

    ``depth`` is a 2-D numpy array: float32 (metres for a pinhole camera, the raw 8-bit values for ABW; NaN
    or 0 = no data), or uint16 with ``depth_scale`` metres per unit (0 = no data). It is read in place (any
    strides) into the pipeline's own grid; it is not modified. ``seed`` overrides the configuration's.
    Results equal the CLI's (``rangeseg segment``) bit for bit on the same values, camera and configuration.
    """
    return _result(_segment(depth, camera, load_config(config), seed, depth_scale))


class Segmenter:
    """Segments a stream of depth images, keeping the working buffers of the previous one.

    Frames of one size allocate no image-sized memory after the first (and skip the page faults of fresh
    memory); each call gives what :func:`segment` gives, bit for bit. One per thread: a call holds it.

    >>> seg = rangeseg.Segmenter(config)
    >>> for depth in frames:
    ...     result = seg.segment(depth, camera)
    """

    def __init__(self, config: ConfigLike = None, seed: Optional[int] = None) -> None:
        self._inner = _Segmenter(load_config(config), seed)

    def segment(self, depth: np.ndarray, camera: Camera, *, depth_scale: Optional[float] = None) -> Result:
        """As :func:`segment` with this segmenter's configuration and seed."""
        return _result(self._inner.segment(depth, camera, depth_scale))


def _result(raw: Dict[str, Any]) -> Result:
    """A :class:`Result` from the native module's dict."""
    cols = raw["planes"]
    planes = np.zeros(len(cols["label"]), dtype=PLANE_DTYPE)
    for name in PLANE_DTYPE.names:
        planes[name] = cols[name]
    return Result(
        labels=raw["labels"],
        planes=planes,
        edges=raw["edges"],
        c1=raw["c1"],
        c2=raw["c2"],
        timings=dict(raw["timings"]),
    )
