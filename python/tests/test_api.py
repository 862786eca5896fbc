"""Each function of the package against the CLI on the same inputs (issue 45): the same
numbers, exactly, and errors as exceptions that carry the file, line and key."""

import json
import threading

import pandas as pd
import pytest

import forgemon
from conftest import CONFIG, cli

MACHINE = CONFIG / "hammer-lg1000.machine.toml"
STEEL = CONFIG / "steel-16NiCrMo13.process.toml"


def test_simulate_equals_the_cli_blow_for_blow(forgemon_bin):
    want = json.loads(cli(forgemon_bin, "simulate", "--machine", MACHINE, "--process", STEEL, "--v0", "4,3.5,4", "--json").stdout)
    m, p = forgemon.Machine.from_toml(MACHINE), forgemon.Process.from_toml(STEEL)
    got = forgemon.simulate(m, p, [4, 3.5, 4])
    assert len(got) == len(want["blows"]) == 3
    for row, blow in zip(got.to_dict("records"), want["blows"]):
        flat = {**{k: v for k, v in blow.items() if k != "energy"}, **{f"energy.{k}": v for k, v in blow["energy"].items()}}
        assert set(flat) <= set(row)
        for k, v in flat.items():
            assert row[k] == v, k
        # A field another blow has (a measured height the sheet lists for some blows only).
        assert all(pd.isna(row[k]) for k in set(row) - set(flat)), row


def test_replay_equals_the_cli_replay_exported(forgemon_bin, fleet_dir, tmp_path):
    run = fleet_dir / "hammer-a"
    out = tmp_path / "replay.mcap"
    cli(forgemon_bin, "replay", run, "--out", out, "--json")
    cli(forgemon_bin, "export", out, "--parquet", tmp_path / "blows.parquet")
    want = pd.read_parquet(tmp_path / "blows.parquet")
    blows, billets = forgemon.replay(run)
    assert (blows["file"] == str(run)).all()
    pd.testing.assert_frame_equal(blows.drop(columns="file"), want.drop(columns="file"))
    # The billets the replay recorded, as `history export` writes them from a rebuild.
    cli(forgemon_bin, "history", "rebuild", out, "--db", tmp_path / "h.sqlite")
    cli(forgemon_bin, "history", "export", "--db", tmp_path / "h.sqlite", "--table", "billets", "--parquet", tmp_path / "billets.parquet")
    pd.testing.assert_frame_equal(billets, pd.read_parquet(tmp_path / "billets.parquet"))
    assert len(billets) == 2, "the demo's two billets"


def test_read_samples_has_every_sample_of_the_recording(forgemon_bin, fleet_dir):
    f = fleet_dir / "hammer-a" / "forgemon-00002.mcap"
    inspect = json.loads(cli(forgemon_bin, "inspect", f, "--json").stdout)
    (source,) = inspect["sources"]
    s = forgemon.read_samples(f)
    assert list(s.columns) == ["source", "t_s", *source["channels"].split(",")]
    assert len(s) == source["samples"]
    assert (s["t_s"].diff().dropna() > 0).all()
    t0, t1 = s["t_s"].iloc[1000], s["t_s"].iloc[2000]
    w = forgemon.read_samples(f, channels=["load_N"], t0=t0, t1=t1)
    assert list(w.columns) == ["source", "t_s", "load_N"]
    assert len(w) == 1001 and w["load_N"].tolist() == s["load_N"].iloc[1000:2001].tolist()
    with pytest.raises(forgemon.ForgemonError, match="'load' is not a channel; the channels are load_N, disp_m, acc_mps2"):
        forgemon.read_samples(f, channels=["load"])


def test_bad_files_raise_with_the_file_line_and_key_the_cli_names(forgemon_bin, tmp_path):
    bad = tmp_path / "bad.machine.toml"
    lines = MACHINE.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("m1_kg = "))
    lines[at] = lines[at].replace("m1_kg", "m1_kgg")
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(forgemon.ForgemonError) as e:
        forgemon.Machine.from_toml(bad)
    err = e.value
    assert isinstance(err, ValueError)
    assert (err.file, err.line, err.key) == (str(bad), at + 1, "m1_kgg")
    stderr = cli(forgemon_bin, "simulate", "--machine", bad, "--bare", "--v0", "4", check=False).stderr
    assert str(err) in stderr
    with pytest.raises(forgemon.ForgemonError) as e:
        forgemon.replay(tmp_path / "absent.mcap")
    assert e.value.file == str(tmp_path / "absent.mcap")
    with pytest.raises(forgemon.ForgemonError):
        forgemon.simulate(MACHINE, STEEL, [400.0])


def test_the_gil_is_released_while_rust_works(fleet_dir):
    """While one thread reads samples, another runs Python: with the GIL held it could not."""
    ticks, done = [], threading.Event()

    def tick():
        while not done.is_set():
            ticks.append(1)
            done.wait(0.001)

    t = threading.Thread(target=tick)
    t.start()
    before = len(ticks)
    forgemon.read_samples(fleet_dir / "hammer-a")
    during = len(ticks) - before
    done.set()
    t.join()
    assert during > 10, f"the other thread ran {during} times during the call"


@pytest.fixture(scope="module")
def captures(forgemon_bin, tmp_path_factory):
    """Calibration and held-out blows of the example hammer with a hidden contact
    compliance, as `forgemon simulate --captures` writes them (tests/diagnose.rs's recipe)."""
    root = tmp_path_factory.mktemp("captures")
    for name, v0, seed in (("calib", "4.0,4.5,5.0,5.3,5.3", "3"), ("holdout", "4.2,4.8,5.1,5.3,5.3", "4")):
        cli(forgemon_bin, "simulate", "--machine", MACHINE, "--process", STEEL, "--v0", v0, "--effect", "elastic_recovery:k_contact_N_per_m=1.5e9", "--captures", root / name, "--capture-seed", seed)
    return root


def test_identify_writes_what_the_cli_writes(forgemon_bin, captures, tmp_path):
    args = ["--kind", "hammer", "--reference", captures / "calib", "--starts", "2", "--monte-carlo", "8", "--seed", "5"]
    cli(forgemon_bin, "identify", *args, "--out", tmp_path / "cli.toml")
    got = forgemon.identify("hammer", captures / "calib", out=tmp_path / "py.toml", starts=2, monte_carlo=8, seed=5)
    from forgemon import _toml

    want = _toml(tmp_path / "cli.toml")
    assert {k: v for k, v in got.items() if not k.startswith("_")} == want
    assert got["_path"] == str(tmp_path / "py.toml") and got["kind"] == "hammer"


def test_diagnose_reports_what_the_cli_reports(forgemon_bin, captures, tmp_path):
    cli(forgemon_bin, "diagnose", "--machine", MACHINE, "--calib", captures / "calib", "--holdout", captures / "holdout", "--out", tmp_path / "cli")
    want = json.loads((tmp_path / "cli" / "report.json").read_text())
    got = forgemon.diagnose(forgemon.Machine.from_toml(MACHINE), captures / "calib", captures / "holdout")
    assert got == want
    assert got["verdict"]["effect"] == "elastic_recovery"


def test_read_samples_reads_a_capture_directory_file_by_file(captures):
    """A capture directory: each blow file its own source (`capture/blow_NN.csv`), every
    row of every file once."""
    d = captures / "calib"
    s = forgemon.read_samples(d)
    files = sorted(d.glob("blow_*.csv"))
    assert sorted(s["source"].unique()) == sorted(f"capture/{f.name}" for f in files)
    for f in files:
        rows = sum(1 for line in f.read_text().splitlines()[1:] if line.strip() and not line.startswith("#"))
        assert (s["source"] == f"capture/{f.name}").sum() == rows, f.name
