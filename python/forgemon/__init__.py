"""forgemon in Python: the library's verbs as functions, tables as pandas DataFrames.

Each function runs the same code as the `forgemon` command of its name, in this process,
with the GIL released (threads run in parallel); tables cross from Rust as Arrow IPC
streams, never row by row. Errors are `ForgemonError` (a `ValueError`) with `file`, `line`
and `key` set when the error names them.

    import forgemon
    m = forgemon.Machine.from_toml("config/hammer-lg1000.machine.toml")
    p = forgemon.Process.from_toml("config/steel-16NiCrMo13.process.toml")
    blows = forgemon.simulate(m, p, [4.0, 4.0, 4.0])
    blows_df, billets_df = forgemon.replay("forgemon-demo/")
"""

import json
import os
import tempfile

import pyarrow as pa

from ._forgemon import ForgemonError, Machine, Process
from . import _forgemon

__all__ = [
    "ForgemonError",
    "Machine",
    "Process",
    "simulate",
    "replay",
    "read_samples",
    "identify",
    "diagnose",
    "frame",
]


def frame(ipc_bytes):
    """An Arrow IPC stream as a pandas DataFrame (columns typed as Arrow typed them)."""
    return pa.ipc.open_stream(pa.py_buffer(ipc_bytes)).read_all().to_pandas()


def _path(x):
    return os.fspath(x.path if isinstance(x, (Machine, Process)) else x)


def simulate(machine, process, v0s, effects=(), bare=False, raw=False):
    """`forgemon simulate --json`: one row per blow (or bare strike), energies as
    `energy.plastic_J` columns. `machine` and `process` are `Machine`/`Process` objects or
    paths; `effects` are `--effect` specs. With `raw=True`, the CLI's JSON as a dict too."""
    argv = ["--machine", _path(machine), "--v0", ",".join(repr(float(v)) for v in v0s), "--json"]
    if bare:
        argv.append("--bare")
    else:
        argv += ["--process", _path(process)]
    for e in effects:
        argv += ["--effect", e]
    text, table = _forgemon.simulate_json(argv)
    df = frame(table)
    return (df, json.loads(text)) if raw else df


def replay(path, machine=None, process=None, service=None, recipe=None):
    """`forgemon replay PATH`: the blows as `forgemon export` writes them (its columns;
    `file` names PATH) and the billets as `forgemon history export --table billets` writes
    them (`wall_time` the replay's: the device clock), as two DataFrames.
    PATH is a recording, a directory of them (a rotated run) or a capture directory."""
    argv = []
    for flag, value in (("--machine", machine), ("--process", process), ("--service", service), ("--recipe", recipe)):
        if value is not None:
            argv += [flag, _path(value)]
    blows, billets = _forgemon.replay_frames(os.fspath(path), argv)
    return frame(blows), billet_table(billets).to_pandas()


def billet_table(parquet_bytes):
    """The billets as `forgemon history export --table billets --parquet` writes them."""
    import pyarrow.parquet as pq

    return pq.read_table(pa.BufferReader(parquet_bytes))


def read_samples(path, channels=(), t0=None, t1=None):
    """The samples of a recording (or a directory of them, or a capture directory):
    `source`, `t_s` (device time, s) and one column per channel (`load_N`, `disp_m`,
    `acc_mps2`; all when `channels` is empty), for `t0 <= t_s <= t1`."""
    return frame(_forgemon.read_samples(os.fspath(path), list(channels), t0, t1))


def _toml(path):
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    with open(path, "rb") as f:
        return tomllib.load(f)


def identify(kind, reference, out=None, process=None, bare=False, initial=None, ram_kg=None, seed=1, monte_carlo=200, starts=None):
    """`forgemon identify`: fit the machine model to the reference blows. Returns the
    written `machine.toml` as a dict, with `_path` and `_report` (the HTML report) added.
    `out` defaults to a file in a new temporary directory."""
    out = os.fspath(out) if out is not None else os.path.join(tempfile.mkdtemp(prefix="forgemon-identify-"), "machine.toml")
    argv = ["--kind", kind, "--reference", os.fspath(reference), "--out", out, "--seed", str(seed), "--monte-carlo", str(monte_carlo)]
    for flag, value in (("--process", process), ("--initial", initial)):
        if value is not None:
            argv += [flag, _path(value)]
    if ram_kg is not None:
        argv += ["--ram-kg", repr(float(ram_kg))]
    if starts is not None:
        argv += ["--starts", str(int(starts))]
    if bare:
        argv.append("--bare")
    _forgemon.identify_run(argv)
    result = _toml(out)
    result["_path"] = out
    result["_report"] = os.path.splitext(out)[0] + ".html"
    return result


def diagnose(machine, calib, holdout, out=None):
    """`forgemon diagnose`: where model and measurement part and which effect explains it.
    Returns `report.json` (docs/interfaces.md) as a dict; `out` (the report's directory)
    defaults to a new temporary directory."""
    out = os.fspath(out) if out is not None else tempfile.mkdtemp(prefix="forgemon-diagnose-")
    _forgemon.diagnose_run(["--machine", _path(machine), "--calib", os.fspath(calib), "--holdout", os.fspath(holdout), "--out", out])
    with open(os.path.join(out, "report.json")) as f:
        return json.load(f)
