"""Type stubs of the native module ``rangeseg._rangeseg`` (Rust, PyO3)."""

import os
from typing import Any, Dict, Optional, Tuple, Union

import numpy as np

class RangesegError(Exception):
    """Base class of rangeseg's errors."""

class ReadError(RangesegError):
    """A depth file could not be read; the message is the CLI's."""

class ConfigError(RangesegError):
    """A configuration could not be used; the message is the CLI's."""

class Pinhole:
    """A pinhole depth camera: Z = value·depth_scale, X = (x − cx)·Z/fx, Y = (y − cy)·Z/fy."""

    fx: float
    fy: float
    cx: float
    cy: float
    depth_scale: float
    def __init__(self, fx: float, fy: float, cx: float, cy: float, depth_scale: float = 1.0) -> None: ...

class ABW:
    """The ABW structured-light scanner, calibration 0 or 1; depth values are raw 8-bit range values."""

    calibration: int
    def __init__(self, calibration: int) -> None: ...

class Grid:
    """No calibration: the 3D point of pixel (x, y) with value v is (x, y, v)."""

    def __init__(self) -> None: ...

Camera = Union[Pinhole, ABW, Grid]

class Config:
    """A validated pipeline configuration (the tables of configs/default.toml)."""

    def __init__(self) -> None: ...
    @staticmethod
    def from_path(path: Union[str, "os.PathLike[str]"]) -> "Config": ...
    @staticmethod
    def from_toml(text: str, name: str = "<config>") -> "Config": ...
    @staticmethod
    def from_json(text: str, name: str = "<config dict>") -> "Config": ...
    def to_toml(self) -> str: ...
    @property
    def seed(self) -> int: ...

def parse_camera(spec: str) -> Camera:
    """A CLI camera spec: abw0, abw1, grid or pinhole:fx,fy,cx,cy[,depth_scale]; ValueError if malformed."""

def read(
    path: Union[str, "os.PathLike[str]"],
    camera: Optional[Camera] = None,
    depth_scale: Optional[float] = None,
    nyu_grey: bool = False,
) -> Tuple[np.ndarray, Camera]:
    """Reads a depth file (ABW rasterfile, PGM, PNG, TIFF, PCD): float32 depth (NaN = no data) and its camera.

    nyu_grey=True reads the 8-bit NYU frames of Jin et al. as the CLI's --nyu-grey (depth = 370 - grey)."""

def read_bytes(
    data: bytes,
    name: str,
    camera: Optional[Camera] = None,
    depth_scale: Optional[float] = None,
    nyu_grey: bool = False,
) -> Tuple[np.ndarray, Camera]:
    """Like read, on a file's bytes; name chooses the ABW calibration and names the file in errors."""

class Segmenter:
    """The pipeline on a stream of frames, reusing the previous frame's buffers."""

    def __init__(self, config: Optional[Config] = None, seed: Optional[int] = None) -> None: ...
    def segment(
        self, depth: np.ndarray, camera: Camera, depth_scale: Optional[float] = None
    ) -> Dict[str, Any]: ...

def segment(
    depth: np.ndarray,
    camera: Camera,
    config: Optional[Config] = None,
    seed: Optional[int] = None,
    depth_scale: Optional[float] = None,
) -> Dict[str, Any]:
    """The pipeline on a 2-D float32 or uint16 array, GIL released: labels, edges, c1, c2, planes, timings."""
