"""Batch segmentation on a Ray cluster: depth files in, one Parquet table of planes out.

    python -m rangeseg.ray INPUTS... --out planes.parquet [--address ray://HOST:10001] [--labels-dir DIR]

INPUTS are files or directories, local or on any filesystem pyarrow reaches (``s3://``, ``gs://`` …). They are
read as a Ray Dataset (``ray.data.read_binary_files``), segmented in parallel by ``map_batches`` on the
cluster's workers (one CPU per image), and the planes are streamed, in input order, into one Parquet file
with one row per final region: file, label, normal, d, centroid, pixels, rms, bbox. Without ``--address``
the command starts a local Ray with ``--workers`` CPUs (default: all). ``--labels-dir`` (a directory every
worker can write, e.g. a shared filesystem) receives each image's label array as ``STEM.labels.npy``.
Rows are the same as :func:`plane_table` gives for each file in a single process.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import rangeseg

#: The Parquet table's columns.
SCHEMA = pa.schema(
    [
        ("file", pa.string()),
        ("label", pa.int32()),
        ("normal", pa.list_(pa.float64(), 3)),
        ("d", pa.float64()),
        ("centroid", pa.list_(pa.float64(), 3)),
        ("pixels", pa.int64()),
        ("rms", pa.float64()),
        ("bbox", pa.list_(pa.int32(), 4)),
    ]
)

#: File extensions picked up inside a directory (as ``rangeseg segment`` does).
RANGE_EXTENSIONS = (".range", ".png", ".pgm", ".tif", ".tiff", ".pcd")


def plane_table(
    file: str,
    data: bytes,
    camera: Optional[str] = None,
    config_toml: Optional[str] = None,
    seed: Optional[int] = None,
    depth_scale: Optional[float] = None,
    labels_dir: Optional[str] = None,
) -> pa.Table:
    """The plane rows of one depth file's bytes (``file`` names it, and chooses the ABW calibration).

    ``camera`` is a CLI camera spec (``abw0``, ``abw1``, ``grid``, ``pinhole:fx,fy,cx,cy[,scale]``),
    ``config_toml`` a configuration's TOML text.
    """
    cam = rangeseg.parse_camera(camera) if camera else None
    depth, cam = rangeseg.read_bytes(data, file, camera=cam, depth_scale=depth_scale)
    config = rangeseg.Config.from_toml(config_toml) if config_toml is not None else None
    result = rangeseg.segment(depth, cam, config, seed)
    if labels_dir is not None:
        _save_atomic(os.path.join(labels_dir, _stem(file) + ".labels.npy"), result.labels)
    p = result.planes
    n = len(p)
    return pa.table(
        {
            "file": pa.array([file] * n, pa.string()),
            "label": pa.array(p["label"], pa.int32()),
            "normal": _fixed(p["normal"], pa.float64(), 3),
            "d": pa.array(p["d"], pa.float64()),
            "centroid": _fixed(p["centroid"], pa.float64(), 3),
            "pixels": pa.array(p["pixels"], pa.int64()),
            "rms": pa.array(p["rms"], pa.float64()),
            "bbox": _fixed(p["bbox"], pa.int32(), 4),
        },
        schema=SCHEMA,
    )


def _fixed(values: np.ndarray, typ: pa.DataType, k: int) -> pa.Array:
    flat = pa.array(np.ascontiguousarray(values).reshape(-1), typ)
    return pa.FixedSizeListArray.from_arrays(flat, k)


def _stem(file: str) -> str:
    base = file.rstrip("/").rsplit("/", 1)[-1]
    return base.rsplit(".", 1)[0] if "." in base else base


def _save_atomic(path: str, array: np.ndarray) -> None:
    d = os.path.dirname(path) or "."
    fd, tmp = tempfile.mkstemp(dir=d, prefix="." + os.path.basename(path) + ".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            np.save(f, array)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _segment_batch(batch: pa.Table, **kwargs: Any) -> pa.Table:
    """map_batches: the plane rows of every file in a batch of ``read_binary_files`` rows."""
    tables = [
        plane_table(path, data, **kwargs)
        for path, data in zip(batch.column("path").to_pylist(), batch.column("bytes").to_pylist())
    ]
    return pa.concat_tables(tables) if tables else SCHEMA.empty_table()


def expand_inputs(inputs: Sequence[str]) -> List[str]:
    """Local files as given (made absolute), the range files inside local directories (sorted), and remote
    URIs unchanged (Ray lists remote directories itself)."""
    out: List[str] = []
    for item in inputs:
        if "://" in item:
            out.append(item)
        elif os.path.isdir(item):
            found = sorted(
                os.path.join(item, n)
                for n in os.listdir(item)
                if n.lower().endswith(RANGE_EXTENSIONS) and os.path.isfile(os.path.join(item, n))
            )
            if not found:
                raise SystemExit(f"error: {item}: no range files in directory")
            out.extend(os.path.abspath(f) for f in found)
        elif os.path.isfile(item):
            out.append(os.path.abspath(item))
        else:
            raise SystemExit(f"error: {item}: no such file or directory")
    return out


def run(
    inputs: Sequence[str],
    out: str,
    address: Optional[str] = None,
    workers: Optional[int] = None,
    labels_dir: Optional[str] = None,
    camera: Optional[str] = None,
    config: Optional[str] = None,
    seed: Optional[int] = None,
    depth_scale: Optional[float] = None,
) -> Dict[str, float]:
    """Segments ``inputs`` on Ray and writes the planes to ``out`` (atomically); returns counts and seconds."""
    import ray

    files = expand_inputs(inputs)
    config_toml = rangeseg.load_config(config).to_toml() if config is not None else None
    if camera:
        rangeseg.parse_camera(camera)  # fail early, on the driver, with the CLI's message
    if labels_dir is not None:
        os.makedirs(labels_dir, exist_ok=True)
        labels_dir = os.path.abspath(labels_dir)
    started_here = not ray.is_initialized()
    if started_here:
        if address is None:
            ray.init(num_cpus=workers or os.cpu_count(), include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
    try:
        ctx = ray.data.DataContext.get_current()
        ctx.execution_options.preserve_order = True  # rows in input order: the same table on any cluster
        ctx.enable_progress_bars = False
        t0 = time.perf_counter()
        # A few blocks per CPU (each block one task that reads and segments its files): per-task overhead stays
        # small next to the segmentation, and every CPU still gets work until the end.
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        if address is not None and workers:
            cpus = min(cpus, workers)
        blocks = max(1, min(len(files), 4 * cpus))
        ds = ray.data.read_binary_files(files, include_paths=True, override_num_blocks=blocks)
        ds = ds.map_batches(
            _segment_batch,
            batch_size=1,
            batch_format="pyarrow",
            num_cpus=1,
            concurrency=workers if address is not None else None,
            fn_kwargs=dict(
                camera=camera, config_toml=config_toml, seed=seed, depth_scale=depth_scale, labels_dir=labels_dir
            ),
        )
        rows = _write_parquet(ds, out)
        seconds = time.perf_counter() - t0
    finally:
        if started_here:
            ray.shutdown()
    return {"files": len(files), "rows": rows, "seconds": seconds}


def _write_parquet(ds: Any, out: str) -> int:
    """Streams the dataset's batches into one Parquet file, written beside ``out`` and renamed over it."""
    d = os.path.dirname(os.path.abspath(out))
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=d, prefix="." + os.path.basename(out) + ".tmp")
    os.close(fd)
    rows = 0
    try:
        with pq.ParquetWriter(tmp, SCHEMA) as writer:
            for batch in ds.iter_batches(batch_format="pyarrow", batch_size=None):
                if batch.num_rows:
                    writer.write_table(batch.select(SCHEMA.names).cast(SCHEMA))
                    rows += batch.num_rows
        os.replace(tmp, out)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return rows


def main(argv: Optional[Sequence[str]] = None) -> int:
    """The command line (see the module's docstring)."""
    ap = argparse.ArgumentParser(prog="python -m rangeseg.ray", description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help="depth files or directories (local paths or URIs)")
    ap.add_argument("--out", required=True, help="the Parquet file to write")
    ap.add_argument("--address", help="Ray cluster address (ray://HOST:10001); default: start a local Ray")
    ap.add_argument("--workers", type=int, help="local Ray: CPUs to start (default: all); cluster: concurrent tasks")
    ap.add_argument("--labels-dir", help="also write each image's labels as STEM.labels.npy here")
    ap.add_argument("--camera", help="abw0, abw1, grid or pinhole:fx,fy,cx,cy[,depth_scale]")
    ap.add_argument("--config", help="configuration TOML file (default: the built-in defaults)")
    ap.add_argument("--seed", type=int, help="seed (overrides the configuration's)")
    ap.add_argument("--depth-scale", type=float, help="metres per stored unit of PGM, PNG and TIFF samples")
    a = ap.parse_args(argv)
    if a.workers is not None and a.workers < 1:
        ap.error("--workers must be at least 1")
    try:
        stats = run(
            a.inputs,
            a.out,
            address=a.address,
            workers=a.workers,
            labels_dir=a.labels_dir,
            camera=a.camera,
            config=a.config,
            seed=a.seed,
            depth_scale=a.depth_scale,
        )
    except Exception as e:  # a worker's error comes wrapped in a RayTaskError: report its cause
        cause = e
        while getattr(cause, "cause", None) is not None and cause is not cause.cause:
            cause = cause.cause
        if not isinstance(cause, (rangeseg.RangesegError, ValueError, OSError)):
            raise
        print(f"error: {cause}", file=sys.stderr)
        return 1
    print(
        f"{stats['files']} files, {stats['rows']} planes in {stats['seconds']:.2f} s "
        f"({stats['files'] / stats['seconds']:.1f} files/s) -> {a.out}",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
