"""Throughput of `python -m rangeseg.ray` on a local Ray with 1 and 2 workers, over the 40 synthetic images.

    cargo xtask gen-data             # once: writes data/synthetic-abw/
    python python/bench_ray.py [--data data/synthetic-abw] [--repeat 3]

For each worker count it starts a local Ray with that many CPUs, runs the 40 files once (checking that the rows
equal a single-process loop over the files; this also starts the worker processes) and then times dataset →
Parquet file over the files repeated. It prints the single-process loop's throughput too.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import tempfile
import time

import pyarrow as pa
import pyarrow.parquet as pq

# This script sits beside the package's sources (python/rangeseg, without the compiled module): import the
# installed package instead.
sys.path = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(os.path.abspath(__file__))]
from rangeseg import ray as rray  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=os.path.join(os.path.dirname(__file__), "..", "data", "synthetic-abw"))
    ap.add_argument("--repeat", type=int, default=3, help="pass over the files this many times per run")
    a = ap.parse_args()
    files = sorted(glob.glob(os.path.join(a.data, "abw.*.range")))
    if len(files) != 40:
        raise SystemExit(f"expected the 40 synthetic images in {a.data}, found {len(files)}: run cargo xtask gen-data")
    files = [os.path.abspath(f) for f in files]

    t = time.perf_counter()
    single = pa.concat_tables([rray.plane_table(f, open(f, "rb").read()) for f in files])
    single_rate = len(files) / (time.perf_counter() - t)
    print(f"single process, no Ray: {single_rate:.1f} images/s ({single.num_rows} planes)")

    import ray

    rates = {}
    with tempfile.TemporaryDirectory() as tmp:
        for workers in (1, 2):
            # One local Ray per worker count: the first run (the row check) starts its worker processes and
            # imports the package in them; the timed run reuses them, as a long batch job would.
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
            try:
                out = os.path.join(tmp, f"planes{workers}.parquet")
                rray.run(files, out, workers=workers)
                assert pq.read_table(out).to_pylist() == single.to_pylist(), f"{workers} workers: rows differ"
                stats = rray.run(files * a.repeat, out, workers=workers)
            finally:
                ray.shutdown()
            rates[workers] = stats["files"] / stats["seconds"]
            print(f"Ray, {workers} worker(s): {rates[workers]:.1f} images/s ({stats['files']} images, "
                  f"{stats['seconds']:.2f} s)")
    print(f"speed-up 2 vs 1 workers: {rates[2] / rates[1]:.2f}x (same rows as the single-process run: yes)")


if __name__ == "__main__":
    main()
