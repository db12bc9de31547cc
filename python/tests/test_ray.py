"""`python -m rangeseg.ray` on a local Ray with 2 workers gives the rows of a single-process run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

if os.environ.get("RANGESEG_REQUIRE_RAY"):
    import pyarrow.parquet as pq
    import ray  # noqa: F401
else:
    pq = pytest.importorskip("pyarrow.parquet")
    pytest.importorskip("ray")

import rangeseg  # noqa: E402
from rangeseg import ray as rray  # noqa: E402


def test_two_workers_give_the_single_process_rows(scene_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "planes.parquet"
    labels_dir = tmp_path / "labels"
    proc = subprocess.run(
        [sys.executable, "-m", "rangeseg.ray", str(scene_dir), "--out", str(out), "--workers", "2",
         "--labels-dir", str(labels_dir), "--seed", "3"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    table = pq.read_table(out)
    assert table.schema.equals(rray.SCHEMA)

    files = rray.expand_inputs([str(scene_dir)])
    assert len(files) == 3
    single = [rray.plane_table(f, Path(f).read_bytes(), seed=3) for f in files]
    import pyarrow as pa

    expected = pa.concat_tables(single)
    assert expected.num_rows >= 15
    # Same rows in the same (input) order, every value bit for bit.
    assert table.to_pylist() == expected.to_pylist()

    for f in files:
        stem = Path(f).name.rsplit(".", 1)[0]
        labels = np.load(labels_dir / f"{stem}.labels.npy")
        depth, camera = rangeseg.read(f)
        assert np.array_equal(labels, rangeseg.segment(depth, camera, seed=3).labels)


def test_bad_input_is_an_error_without_output(tmp_path: Path) -> None:
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not a png")
    out = tmp_path / "planes.parquet"
    proc = subprocess.run(
        [sys.executable, "-m", "rangeseg.ray", str(junk), "--out", str(out), "--workers", "1"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 1
    assert f"{junk}:" in proc.stderr
    assert not out.exists() and os.listdir(tmp_path) == ["junk.png"]
