"""Shared fixtures: synthetic ABW-like range files written by numpy, and the CLI binary built by cargo."""

from __future__ import annotations

import json
import os
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


def scene(width: int = 256, height: int = 224, shift: int = 0) -> np.ndarray:
    """A raw 8-bit ABW-like range image (larger = farther, 0 = no data): a tilted wall, a floor, a box with two
    visible faces, a wedge, and a projector shadow; ``shift`` moves the objects sideways."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    v = 200.0 + 0.05 * x - 0.03 * y  # wall
    floor = y > 160
    v[floor] = (200.0 + 0.05 * x - 0.03 * 160 - 0.55 * (y - 160))[floor]
    bx = x - shift
    top = (bx >= 50) & (bx < 120) & (y >= 60) & (y < 80)
    front = (bx >= 50) & (bx < 120) & (y >= 80) & (y < 190)
    v[front] = (110.0 + 0.08 * bx + 0.02 * y)[front]
    v[top] = (110.0 + 0.08 * bx + 0.02 * 80 + 0.9 * (80 - y))[top]
    wedge = (bx >= 150) & (bx < 220) & (y >= 90) & (y < 185)
    v[wedge] = (95.0 + 0.45 * np.abs(bx - 185) + 0.05 * y)[wedge]
    shadow = (bx >= 120) & (bx < 126) & (y >= 70) & (y < 190)
    out = np.clip(np.rint(v), 1, 254).astype(np.uint8)
    out[shadow] = 0
    return out


def write_sun_raster(path: Path, raw: np.ndarray) -> None:
    """An 8-bit Sun rasterfile (the ABW `.range` format), rows padded to an even length."""
    h, w = raw.shape
    padded = np.zeros((h, w + (w & 1)), dtype=np.uint8)
    padded[:, :w] = raw
    header = struct.pack(">8I", 0x59A66A95, w, h, 8, padded.size, 1, 0, 0)
    path.write_bytes(header + padded.tobytes())


def write_pgm16(path: Path, values: np.ndarray) -> None:
    """A binary 16-bit PGM (big-endian samples)."""
    h, w = values.shape
    path.write_bytes(f"P5\n{w} {h}\n65535\n".encode() + values.astype(">u2").tobytes())


@pytest.fixture(scope="session")
def scene_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One synthetic range file (calibration 0)."""
    path = tmp_path_factory.mktemp("scene") / "scene.range"
    write_sun_raster(path, scene())
    return path


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A few synthetic range files with the objects in different places."""
    d = tmp_path_factory.mktemp("scenes")
    for i, shift in enumerate([0, 12, -9]):
        write_sun_raster(d / f"scene{i}.range", scene(shift=shift))
    return d


@pytest.fixture(scope="session")
def cli() -> Path:
    """The `rangeseg` binary: $RANGESEG_CLI, or built now with `cargo build --bin rangeseg`."""
    if "RANGESEG_CLI" in os.environ:
        return Path(os.environ["RANGESEG_CLI"])
    proc = subprocess.run(
        ["cargo", "build", "--quiet", "--bin", "rangeseg", "--message-format=json"],
        cwd=REPO,
        check=True,
        stdout=subprocess.PIPE,
    )
    for line in proc.stdout.decode().splitlines():
        msg = json.loads(line)
        if msg.get("reason") == "compiler-artifact" and msg.get("executable") and msg["target"]["name"] == "rangeseg":
            return Path(msg["executable"])
    raise RuntimeError("cargo build did not report the rangeseg executable")
