"""Re-analysis of a fleet's recordings on a Dask cluster.

    from dask.distributed import Client
    import forgemon.fleet
    summary = forgemon.fleet.reanalyse("/data/*/*.mcap", out="/data/reanalysis",
                                       machine="new.machine.toml", client=Client("tcp://scheduler:8786"))

How the work is cut. A recording's machine is the name of the directory it lies in (or
what `machine_of(path)` says). Each machine's recordings are ordered by the log time of
their first message and cut into runs: a file continues the one before it only when every
sample source goes on where it stopped (the next batch sequence number, a later device
time) and it starts on the same UTC day; a height chain crosses a file boundary only then.
Each run is one task, replayed in order as `forgemon replay` replays a rotated directory,
and runs are independent, so the cluster takes them in parallel.

What it writes: Parquet under `out`, partitioned by machine and date:
`blows/machine=M/date=YYYY-MM-DD/<first file>.parquet` with the columns of `forgemon
export` (each blow attributed to the file that recorded it, with its wall time), and
`billets/machine=M/date=.../<first file>.parquet` with `history export`'s billet columns. A task writes
its files under a temporary name and renames them, so a retried or repeated task leaves
one copy. Failed tasks are retried (`retries`); a run that still fails is named in the
summary with its error and the others go on. A file whose bounds cannot be read is named
and left out. Works the same on a `LocalCluster` and a multi-node cluster whose workers
see `out` and the recordings at the same paths.
"""

import datetime as _dt
import glob as _glob
import os

import pyarrow as pa
import pyarrow.parquet as pq

from . import _forgemon
from . import billet_table


def _files(paths_or_glob):
    items = [paths_or_glob] if isinstance(paths_or_glob, (str, os.PathLike)) else list(paths_or_glob)
    out = []
    for item in items:
        item = os.fspath(item)
        if os.path.isdir(item):
            out += sorted(os.path.join(item, n) for n in os.listdir(item) if n.endswith((".mcap", ".mcap.part")))
        elif any(c in item for c in "*?["):
            out += sorted(_glob.glob(item))
        else:
            out.append(item)
    return out


def _day(ns):
    return _dt.datetime.fromtimestamp(ns / 1e9, tz=_dt.timezone.utc).date().isoformat()


def _continues(prev, nxt):
    """Whether the file `nxt` goes on where `prev` stopped: every source of `nxt` was in
    `prev` and its first batch follows `prev`'s last (sequence + 1, later device time)."""
    prev_sources, next_sources = prev[1], nxt[1]
    if not next_sources:
        return False
    for source, (first_seq, _, first_dev, _) in next_sources.items():
        if source not in prev_sources:
            return False
        _, last_seq, _, last_dev = prev_sources[source]
        if first_seq != last_seq + 1 or first_dev <= last_dev:
            return False
    return True


def bounds_of(f):
    """`(file, (first_log_ns, sources), None)`, or `(file, None, error)` when it cannot be
    read. Runs on a worker."""
    try:
        first_log, sources, blows, billets = _forgemon.recording_bounds(f)
    except Exception as e:  # noqa: BLE001 - named in the summary
        return f, None, str(e)
    if first_log is None:
        return f, None, "holds no messages"
    return f, (first_log, sources, blows, billets), None


def plan(paths_or_glob, machine_of=None, client=None):
    """The runs to re-analyse, `[(machine, day, [files], [(recorded blows, recorded
    billets) per file])]`, and
    the files left out with why, `[(file, error)]`. Reads each file once: on `client`'s
    workers when given, else here."""
    machine_of = machine_of or (lambda p: os.path.basename(os.path.dirname(os.path.abspath(p))))
    files = _files(paths_or_glob)
    found = client.gather(client.map(bounds_of, files, pure=False)) if client is not None else [bounds_of(f) for f in files]
    bounds = {f: b for f, b, _ in found if b is not None}
    unreadable = [(f, e) for f, b, e in found if b is None]
    runs = []
    by_machine = {}
    for f in bounds:
        by_machine.setdefault(machine_of(f), []).append(f)
    for machine, files in sorted(by_machine.items()):
        files.sort(key=lambda f: (bounds[f][0], f))
        for f in files:
            day = _day(bounds[f][0])
            last = runs[-1] if runs else None
            if last and last[0] == machine and last[1] == day and _continues(bounds[last[2][-1]], bounds[f]):
                last[2].append(f)
                last[3].append((bounds[f][2], bounds[f][3]))
            else:
                runs.append((machine, day, [f], [(bounds[f][2], bounds[f][3])]))
    return runs, unreadable


def _write(table, path):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = f"{path}.{os.getpid()}.tmp"
    pq.write_table(table, tmp, compression="snappy")
    os.replace(tmp, path)


def _billets_at(table, recorded, blows):
    """The billets with the wall time each was recorded at, matched by its device start time
    `t_start_s` (a re-analysis does not move it), and `first_blow_ns` its first blow's wall
    time in `blows` (attributed the same way); where no file recorded it, the replay's."""
    at = {t: wall for _, billets in recorded for t, wall in billets}
    first = {}
    for b, w in zip(blows.column("billet").to_pylist(), blows.column("wall_time").cast(pa.int64()).to_pylist()):
        first[b] = min(first.get(b, w), w)
    walls = [at.get(t, w) for t, w in zip(table.column("t_start_s").to_pylist(), table.column("wall_time").cast(pa.int64()).to_pylist())]
    firsts = [first.get(b, f) for b, f in zip(table.column("billet").to_pylist(), table.column("first_blow_ns").to_pylist())]
    i = table.schema.get_field_index("wall_time")
    table = table.set_column(i, table.schema.field(i), pa.array(walls, pa.int64()).cast(table.schema.field(i).type))
    j = table.schema.get_field_index("first_blow_ns")
    return table.set_column(j, table.schema.field(j), pa.array(firsts, table.schema.field(j).type))


def run_task(machine, day, files, recorded, out, argv):
    """One run: replay its files in order and write its blows and billets. Returns the
    paths written. Runs on a worker."""
    blows, billets = _forgemon.reanalyse_run(files, [b for b, _ in recorded], argv)
    stem = os.path.basename(files[0]).split(".")[0]
    written = []
    blows = pa.ipc.open_stream(pa.py_buffer(blows)).read_all()
    tables = (("blows", blows), ("billets", _billets_at(billet_table(billets), recorded, blows)))
    for kind, table in tables:
        path = os.path.join(out, kind, f"machine={machine}", f"date={day}", f"{stem}.parquet")
        _write(table, path)
        written.append(path)
    return written


def reanalyse(paths_or_glob, out, machine=None, process=None, client=None, machine_of=None, retries=2):
    """Re-analyse recordings on `client` (a `dask.distributed.Client`; a `LocalCluster`'s
    when None) with `machine` (a `Machine` or a path; the recorded model when None) and
    `process`. Returns `{"runs": n, "written": [...], "failed": [{"files", "error"}],
    "unreadable": [{"file", "error"}]}`."""
    from dask.distributed import Client, as_completed

    argv = []
    for flag, value in (("--machine", machine), ("--process", process)):
        if value is not None:
            argv += [flag, os.fspath(getattr(value, "path", value))]
    own = client is None
    client = client or Client(processes=True)
    try:
        runs, unreadable = plan(paths_or_glob, machine_of, client)
        futures = {
            client.submit(run_task, m, d, files, recorded, os.fspath(out), argv, retries=retries, pure=False): files
            for m, d, files, recorded in runs
        }
        written, failed = [], []
        for fut in as_completed(futures):
            try:
                written += fut.result()
            except Exception as e:  # noqa: BLE001 - named in the summary; the run goes on
                failed.append({"files": futures[fut], "error": str(e)})
    finally:
        if own:
            client.close()
    return {
        "runs": len(runs),
        "written": sorted(written),
        "failed": failed,
        "unreadable": [{"file": f, "error": e} for f, e in unreadable],
    }
