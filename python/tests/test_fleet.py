"""Fleet re-analysis on a Dask LocalCluster with 2 worker processes (issue 45): eight
rotated recordings of two machines; the Parquet it writes equals `forgemon export` of the
files, although a worker is killed while it works; an unreadable file is named."""

import os
import signal
import threading
import time

import pandas as pd
import pytest

import forgemon.fleet as fleet
from conftest import cli

distributed = pytest.importorskip("dask.distributed")


def test_reanalysis_equals_the_export_with_a_worker_killed(forgemon_bin, fleet_dir, tmp_path):
    files = sorted(str(p) for p in fleet_dir.glob("*/*.mcap"))
    assert len(files) == 8
    runs, unreadable = fleet.plan(files)
    assert [(m, len(f)) for m, _, f, _ in runs] == [("hammer-a", 4), ("hammer-b", 4)], "each machine's files chain into one run"
    bad = fleet_dir.parent / "broken" / "hammer-c"
    bad.mkdir(parents=True, exist_ok=True)
    (bad / "forgemon-00001.mcap").write_bytes(b"not an mcap file")
    out = tmp_path / "out"
    killed = []
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, distributed.Client(cluster) as client:

        def kill_a_busy_worker():
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not killed:
                busy = [w for w, tasks in client.processing().items() if tasks]
                if busy:
                    pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                time.sleep(0.02)

        killer = threading.Thread(target=kill_a_busy_worker)
        killer.start()
        summary = fleet.reanalyse([*files, str(bad / "forgemon-00001.mcap")], out=out, client=client)
        killer.join()
    assert killed, "no worker was killed while it worked"
    assert summary["failed"] == [], summary
    assert [u["file"] for u in summary["unreadable"]] == [str(bad / "forgemon-00001.mcap")]
    got = pd.read_parquet(out / "blows")
    assert sorted(got["machine"].unique()) == ["hammer-a", "hammer-b"]
    cli(forgemon_bin, "export", *files, "--parquet", tmp_path / "export.parquet")
    want = pd.read_parquet(tmp_path / "export.parquet")
    got = got.drop(columns=["machine", "date"]).sort_values(["file", "blow"]).reset_index(drop=True)
    want = want.sort_values(["file", "blow"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(got, want, check_dtype=False)
    # The billets as `history export` writes them from a database rebuilt from the files.
    cli(forgemon_bin, "history", "rebuild", *files, "--db", tmp_path / "h.sqlite")
    cli(forgemon_bin, "history", "export", "--db", tmp_path / "h.sqlite", "--table", "billets", "--parquet", tmp_path / "billets.parquet")
    want = pd.read_parquet(tmp_path / "billets.parquet").sort_values(["wall_time", "t_start_s"]).reset_index(drop=True)
    got = pd.read_parquet(out / "billets").drop(columns=["machine", "date"]).sort_values(["wall_time", "t_start_s"]).reset_index(drop=True)
    assert len(got) == 4, "two billets per machine"
    pd.testing.assert_frame_equal(got, want, check_dtype=False)
