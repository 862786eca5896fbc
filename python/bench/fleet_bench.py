"""Bench: fleet re-analysis throughput on 1 and 2 local Dask workers, against the CLI
replaying the same runs one after another in this run (the anchor), and the Arrow
round-trip cost of `read_samples` per million samples.

    FORGEMON_BIN=target/release/forgemon python3 python/bench/fleet_bench.py [--repeats 3]

Prints one table; the ratios are to the anchor measured in the same run, each figure the
median of the repeats with its min-max as the noise. docs/performance.md shows how to read
it and projects 500 TB from the per-core rate.
"""

import argparse
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path


def timed(fn, repeats):
    """Median, min and max wall time of `fn()` over `repeats` runs."""
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), min(ts), max(ts)


def main():
    import forgemon
    import forgemon.fleet as fleet
    from forgemon import _forgemon
    from dask.distributed import Client, LocalCluster

    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--keep", help="make the recordings here and keep them")
    a = ap.parse_args()
    bin_ = os.environ.get("FORGEMON_BIN") or shutil.which("forgemon")
    root = Path(a.keep or tempfile.mkdtemp(prefix="forgemon-fleet-bench-"))
    machines = [f"hammer-{c}" for c in "abcd"]
    for m in machines:
        if not any((root / m).glob("*.mcap")):
            subprocess.run([bin_, "demo", "--fast", "--billets", "2", "--rotate-mib", "5", "--dir", root / m], check=True, capture_output=True)
            (root / m / "history.sqlite").unlink(missing_ok=True)
    files = sorted(str(p) for p in root.glob("*/*.mcap"))
    mb = sum(os.path.getsize(f) for f in files) / 1e6
    runs, _ = fleet.plan(files)
    print(f"{len(files)} recordings, {mb:.0f} MB, {len(runs)} runs, {os.cpu_count()} cores")

    def anchor():
        for _, _, fs, _ in runs:
            subprocess.run([bin_, "replay", os.path.dirname(fs[0]), "--json"], check=True, capture_output=True)

    rows = [("anchor: forgemon replay, runs one after another", timed(anchor, a.repeats))]
    for n in (1, 2):
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as c, Client(c) as client:
            out = Path(tempfile.mkdtemp(prefix="forgemon-fleet-out-"))
            # One warm-up run: the workers import forgemon once.
            fleet.reanalyse(files, out=out, client=client)
            rows.append((f"fleet.reanalyse, {n} worker(s)", timed(lambda: fleet.reanalyse(files, out=out, client=client), a.repeats)))
            shutil.rmtree(out)
    base = rows[0][1][0]
    print(f"{'':50} {'s (median, min-max)':>24} {'files/s':>8} {'MB/s':>7} {'vs anchor':>9}")
    for name, (med, lo, hi) in rows:
        print(f"{name:50} {med:8.2f} ({lo:.2f}-{hi:.2f}) {len(files) / med:8.2f} {mb / med:7.1f} {base / med:8.2f}x")
    per_core = mb / rows[1][1][0]
    print(f"per-core rate (1 worker): {per_core:.1f} MB/s")
    for nodes, cores in ((10, 16), (50, 32), (100, 32)):
        days = 500e12 / (per_core * 1e6 * nodes * cores) / 86400
        print(f"500 TB on {nodes} nodes x {cores} cores at that rate: {days:.1f} days")

    # Arrow round trip: Rust decodes and writes IPC (`_forgemon.read_samples`); the package
    # then reads the stream with pyarrow and makes a DataFrame (`forgemon.read_samples`).
    big = max(files, key=os.path.getsize)
    n = len(forgemon.read_samples(big))
    rust = timed(lambda: _forgemon.read_samples(big, [], None, None), a.repeats * 2)
    full = timed(lambda: forgemon.read_samples(big), a.repeats * 2)
    per = 1e6 / n
    print(f"read_samples of {n} samples: Rust decode + IPC {rust[0] * per * 1e3:.1f} ms/1M samples "
          f"({rust[1] * per * 1e3:.1f}-{rust[2] * per * 1e3:.1f}); with pyarrow -> DataFrame {full[0] * per * 1e3:.1f} ms/1M "
          f"({full[1] * per * 1e3:.1f}-{full[2] * per * 1e3:.1f}); Arrow round trip {(full[0] - rust[0]) * per * 1e3:.1f} ms/1M samples")
    if not a.keep:
        shutil.rmtree(root)


if __name__ == "__main__":
    main()
