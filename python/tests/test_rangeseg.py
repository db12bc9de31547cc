"""The Python package against the CLI: reading, segmenting, planes, configurations, errors, the GIL."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import rangeseg
from conftest import scene, write_pgm16


def cli_error(cli: Path, *args: str) -> str:
    """What the CLI prints after `error: ` when it fails (to the end of its output, trailing space removed)."""
    proc = subprocess.run([str(cli), *args], capture_output=True, text=True)
    assert proc.returncode != 0, proc
    assert proc.stderr.startswith("error: "), proc.stderr
    return proc.stderr[len("error: ") :].rstrip()


def test_read_abw_raster(scene_file: Path) -> None:
    depth, camera = rangeseg.read(scene_file)
    raw = scene()
    assert depth.dtype == np.float32 and depth.shape == raw.shape
    assert camera == rangeseg.ABW(0)
    assert np.array_equal(np.isnan(depth), raw == 0)
    assert np.array_equal(depth[raw != 0], raw[raw != 0].astype(np.float32))
    same, _ = rangeseg.read_bytes(scene_file.read_bytes(), "abw.test.19.range")
    assert np.array_equal(same, depth, equal_nan=True)
    assert rangeseg.read_bytes(scene_file.read_bytes(), "abw.test.19.range")[1] == rangeseg.ABW(1)


def test_read_16bit_with_depth_scale_and_camera(tmp_path: Path) -> None:
    values = np.array([[0, 1000, 2500], [65535, 3, 7]], dtype=np.uint16)
    path = tmp_path / "d.pgm"
    write_pgm16(path, values)
    raw, camera = rangeseg.read(path)
    assert camera == rangeseg.Grid() and np.isnan(raw[0, 0]) and raw[0, 1] == 1000.0
    pin = rangeseg.Pinhole(500.0, 500.0, 1.0, 0.5)
    metres, camera = rangeseg.read(path, camera=pin, depth_scale=0.001)
    assert camera == pin
    expected = (values.astype(np.float64) * 0.001).astype(np.float32)
    assert np.array_equal(metres[values != 0], expected[values != 0])


def test_read_nyu_grey_as_the_cli(scene_file: Path, cli: Path) -> None:
    raw = scene()
    depth, camera = rangeseg.read(scene_file, nyu_grey=True)
    assert np.array_equal(np.isnan(depth), raw == 0)
    assert np.array_equal(depth[raw != 0], (370.0 - raw[raw != 0]).astype(np.float32))
    info = subprocess.run([str(cli), "info", "--nyu-grey", str(scene_file)], capture_output=True, text=True)
    assert f"fx={camera.fx:.2f} fy={camera.fy:.2f}" in info.stdout, (camera, info.stdout)
    same, _ = rangeseg.read_bytes(scene_file.read_bytes(), "abw.test.19.range", nyu_grey=True)
    assert np.array_equal(same, depth, equal_nan=True)
    grid, cam = rangeseg.read(scene_file, camera=rangeseg.Grid(), nyu_grey=True)
    assert cam == rangeseg.Grid() and np.array_equal(grid, depth, equal_nan=True)
    with pytest.raises(ValueError):
        rangeseg.read(scene_file, depth_scale=0.001, nyu_grey=True)


def test_read_errors_carry_the_cli_message(tmp_path: Path, cli: Path) -> None:
    junk = tmp_path / "x.dat"
    junk.write_bytes(b"hello world, not an image")
    missing = tmp_path / "missing.range"
    for path in (junk, missing):
        with pytest.raises(rangeseg.ReadError) as e:
            rangeseg.read(path)
        assert str(e.value).rstrip() == cli_error(cli, "info", str(path))
        assert isinstance(e.value, rangeseg.RangesegError)


def test_segment_equals_the_cli_bit_for_bit(scene_file: Path, cli: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    subprocess.run([str(cli), "segment", str(scene_file), "-o", str(out)], check=True, capture_output=True)
    cli_planes = json.loads((out / "scene.planes.json").read_text())
    summary = json.loads((out / "scene.json").read_text())

    depth, camera = rangeseg.read(scene_file)
    result = rangeseg.segment(depth, camera)
    planes = result.planes
    assert planes.dtype == rangeseg.PLANE_DTYPE
    assert len(planes) == summary["regions_final"] == len(cli_planes["planes"]) >= 5
    for row, want in zip(planes, cli_planes["planes"]):
        assert row["label"] == want["label"]
        assert row["pixels"] == want["pixels"]
        assert row["bbox"].tolist() == want["bbox"]
        assert row["centroid"].tolist() == want["centroid"]
        # JSON numbers are the shortest round-trip text of each f64: equal means bit-identical.
        if want["normal"][0] is None:
            assert np.isnan(row["normal"]).all() and np.isnan(row["d"])
        else:
            assert row["normal"].tolist() == want["normal"] and row["d"] == want["d"]
        assert row["rms"] == want["rms"]

    # Labels: int32, and each plane's pixel count and box are those of its label.
    labels = result.labels
    assert labels.dtype == np.int32 and labels.shape == depth.shape
    assert sorted(set(np.unique(labels).tolist()) - {0}) == planes["label"].tolist()
    for row in planes:
        ys, xs = np.nonzero(labels == row["label"])
        assert len(xs) == row["pixels"]
        assert [xs.min(), ys.min(), xs.max(), ys.max()] == row["bbox"].tolist()

    # Edge maps: the CLI's 8-bit edge PNGs read back (0 = no edge reads as no data).
    for name, ours in (("edges", result.edges), ("c1", result.c1), ("c2", result.c2)):
        theirs, _ = rangeseg.read(out / f"scene.{name}.png")
        assert ours.dtype == np.bool_ and ours.any()
        assert np.array_equal(ours, ~np.isnan(theirs)), name
    assert int(result.edges.sum()) == summary["edge_px"]
    assert set(result.timings) == {"features", "regiongrow", "vcanny", "relax"}


def test_uint16_input_equals_float_metres() -> None:
    rng = np.random.default_rng(7)
    mm = (1500 + 4 * scene().astype(np.int64)).astype(np.uint16)
    mm[rng.random(mm.shape) < 0.01] = 0
    camera = rangeseg.Pinhole(525.0, 525.0, 127.5, 111.5)
    a = rangeseg.segment(mm, camera, depth_scale=0.001)
    metres = (mm.astype(np.float64) * 0.001).astype(np.float32)  # 0 stays 0 = no data
    b = rangeseg.segment(metres, camera)
    assert np.array_equal(a.labels, b.labels) and a.planes.tobytes() == b.planes.tobytes()
    # A strided (non-contiguous) view is read as it is.
    wide = np.zeros((mm.shape[0], 2 * mm.shape[1]), dtype=np.float32)
    wide[:, ::2] = metres
    c = rangeseg.segment(wide[:, ::2], camera)
    assert np.array_equal(c.labels, b.labels) and c.planes.tobytes() == b.planes.tobytes()


def test_decimated_frames_come_back_at_full_size() -> None:
    raw = scene()
    depth = ((1500.0 + 4.0 * raw) * 0.001).astype(np.float32)
    depth[raw == 0] = np.nan
    camera = rangeseg.Pinhole(525.0, 525.0, 127.5, 111.5)
    full = rangeseg.segment(depth, camera)
    fast = rangeseg.segment(depth, camera, config={"pipeline": {"decimate": 2}})
    for a in (fast.labels, fast.edges, fast.c1, fast.c2):
        assert a.shape == depth.shape
    assert int(fast.labels.max()) == len(fast.planes) >= 4
    # The same regions, up to their numbers, at all but a few of the labelled pixels.
    agree = 0
    for label in np.unique(full.labels[full.labels > 0]):
        theirs = fast.labels[full.labels == label]
        agree += np.bincount(theirs[theirs > 0]).max(initial=0)
    assert agree >= 0.9 * np.count_nonzero(full.labels)
    # An ABW image has no decimated camera: it runs at full resolution.
    abw = raw.astype(np.float32)
    abw[raw == 0] = np.nan
    a = rangeseg.segment(abw, rangeseg.ABW(0))
    b = rangeseg.segment(abw, rangeseg.ABW(0), config={"pipeline": {"decimate": 2}})
    assert np.array_equal(a.labels, b.labels) and a.planes.tobytes() == b.planes.tobytes()


def test_segmenter_on_a_stream_equals_segment() -> None:
    camera = rangeseg.ABW(0)
    first = scene().astype(np.float32)
    second = first.copy()
    second[40:60, :] = np.nan
    seg = rangeseg.Segmenter(seed=3)
    for depth in [first, second, first]:
        a = seg.segment(depth, camera)
        b = rangeseg.segment(depth, camera, seed=3)
        assert np.array_equal(a.labels, b.labels) and a.planes.tobytes() == b.planes.tobytes()
        assert np.array_equal(a.edges, b.edges) and np.array_equal(a.c1, b.c1) and np.array_equal(a.c2, b.c2)


def test_config_from_dict_path_and_seed(tmp_path: Path, cli: Path) -> None:
    depth, camera = rangeseg.read_bytes(_scene_bytes(), "scene.range")
    toml_path = tmp_path / "c.toml"
    toml_path.write_text("seed = 5\n[relax]\nsupport_px = 0.0\n")
    from_path = rangeseg.segment(depth, camera, config=toml_path)
    from_dict = rangeseg.segment(depth, camera, config={"seed": 5, "relax": {"support_px": 0}})
    from_seed = rangeseg.segment(depth, camera, config={"relax": {"support_px": 0.0}}, seed=5)
    for r in (from_dict, from_seed):
        assert np.array_equal(r.labels, from_path.labels) and np.array_equal(r.edges, from_path.edges)
    assert rangeseg.load_config(toml_path).seed == 5

    bad = tmp_path / "bad.toml"
    bad.write_text("[relax]\nno_such_key = 1\n")
    with pytest.raises(rangeseg.ConfigError) as e:
        rangeseg.segment(depth, camera, config=bad)
    args = ["segment", str(tmp_path / "x.range"), "-o", str(tmp_path), "--config", str(bad)]
    assert str(e.value).rstrip() == cli_error(cli, *args)
    with pytest.raises(rangeseg.ConfigError, match="no_such_key"):
        rangeseg.load_config({"relax": {"no_such_key": 1}})
    with pytest.raises(rangeseg.ConfigError, match=r"<config dict>: \[relax\]"):
        rangeseg.load_config({"relax": {"support_px": -1.0}})


def _scene_bytes() -> bytes:
    import struct

    raw = scene()
    h, w = raw.shape
    return struct.pack(">8I", 0x59A66A95, w, h, 8, raw.size, 1, 0, 0) + raw.tobytes()


@pytest.mark.parametrize(
    "bad, error, match",
    [
        (np.zeros((8, 8), dtype=np.float64), TypeError, "float32.*uint16.*float64"),
        (np.zeros((8, 8), dtype=np.int32), TypeError, "got dtype int32"),
        (np.zeros(64, dtype=np.float32), ValueError, "2-D"),
        (np.zeros((2, 8, 8), dtype=np.float32), ValueError, "2-D"),
        (np.zeros((0, 8), dtype=np.float32), ValueError, "empty"),
        (np.zeros((8, 0), dtype=np.uint16), ValueError, "empty"),
        ([[1.0, 2.0], [3.0, 4.0]], TypeError, "numpy array"),
        (np.ones((8, 8), dtype=np.uint16), ValueError, "depth_scale"),
    ],
)
def test_bad_arrays_are_errors(bad: object, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        rangeseg.segment(bad, rangeseg.Grid())  # type: ignore[arg-type]


def test_bad_cameras_are_errors() -> None:
    depth = np.ones((8, 8), dtype=np.float32)
    with pytest.raises(TypeError, match="camera must be"):
        rangeseg.segment(depth, "grid")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="0 or 1"):
        rangeseg.ABW(2)
    with pytest.raises(ValueError, match="positive"):
        rangeseg.Pinhole(0.0, 500.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="uint16 depth only"):
        rangeseg.segment(depth, rangeseg.Grid(), depth_scale=0.001)


def test_no_data_image_gives_no_regions() -> None:
    r = rangeseg.segment(np.full((16, 16), np.nan, dtype=np.float32), rangeseg.Grid())
    assert len(r.planes) == 0 and not r.labels.any()


def test_segment_releases_the_gil() -> None:
    """While one thread is inside `segment`, another runs Python code: a heartbeat thread's timestamps fall
    in the middle third of the call (impossible if the call held the GIL, which would block it throughout)."""
    depth = np.tile(scene().astype(np.float32), (3, 3))
    depth[depth == 0] = np.nan
    camera = rangeseg.ABW(0)
    beats: list[float] = []
    stop = threading.Event()

    def heartbeat() -> None:
        while not stop.is_set():
            beats.append(time.perf_counter())
            time.sleep(0.0002)

    t = threading.Thread(target=heartbeat)
    t.start()
    try:
        start = time.perf_counter()
        rangeseg.segment(depth, camera)
        end = time.perf_counter()
    finally:
        stop.set()
        t.join()
    third = (end - start) / 3
    inside = [b for b in beats if start + third < b < end - third]
    assert inside, f"no heartbeat during the middle of a {1e3 * (end - start):.1f} ms call"
