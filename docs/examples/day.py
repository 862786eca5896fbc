# %% [markdown]
# # A day of blows in Python
#
# Load a day of a hammer's recordings, plot the efficiency of every billet, and diagnose
# where the machine model and the measurement part. Plain Python in notebook cells (`# %%`):
# run it as a script (`python3 docs/examples/day.py`, as CI does) or open it in Jupyter
# (jupytext, or VS Code's cells). It needs `pip install ./python matplotlib` and the
# `forgemon` binary (on PATH, or `FORGEMON_BIN`), which makes the example's data.

# %%
import argparse
import os
import shutil
import subprocess
from pathlib import Path

import matplotlib

matplotlib.use(os.environ.get("MPLBACKEND", "Agg"))
import matplotlib.pyplot as plt

import forgemon

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--day", help="a directory of one day's recordings (default: a simulated day, made here)")
parser.add_argument("--out", default="forgemon-example-day", help="where the figures and the data made here go")
args, _ = parser.parse_known_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
BIN = os.environ.get("FORGEMON_BIN") or shutil.which("forgemon") or "forgemon"
CONFIG = Path(__file__).resolve().parents[2] / "config"

# %% [markdown]
# ## Load a day
# Without `--day`, the demo hammer forges six billets of lot 4711, each a little unlike the
# last (`--scatter`), as a plant's billets come.

# %%
day = Path(args.day) if args.day else out / "day"
if not args.day and not any(day.glob("*.mcap")):
    subprocess.run([BIN, "demo", "--fast", "--billets", "6", "--scatter", "--lot", "4711", "--die", "17", "--dir", day], check=True, capture_output=True)
blows, billets = forgemon.replay(day)
print(f"{len(blows)} blows on {len(billets)} billets")
print(billets[["billet", "blows", "h_start_m", "h_end_m", "plastic_J", "efficiency"]].to_string(index=False))

# %% [markdown]
# ## Efficiency per billet
# Each blow's efficiency (plastic over impact energy) against its number on the billet:
# the first blows of a hot billet are efficient; as it thins and cools, blows turn elastic.

# %%
fig, ax = plt.subplots(figsize=(7, 4))
for billet, g in blows.groupby("billet"):
    ax.plot(g["billet_blow"], g["efficiency"], marker="o", label=f"billet {billet}")
ax.set_xlabel("blow on the billet")
ax.set_ylabel("efficiency (plastic / impact energy)")
ax.set_ylim(0, 1)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(out / "efficiency-per-billet.png", dpi=120)
print(f"wrote {out / 'efficiency-per-billet.png'}")
mean = blows.groupby("billet")["efficiency"].mean()
assert ((0 <= mean) & (mean <= 1)).all(), "an efficiency out of [0, 1] would be flagged, never plotted"

# %% [markdown]
# ## Where model and measurement part
# Calibration and held-out blows of a hammer whose contact is softer than its model says
# (made here by `forgemon simulate --captures` with a hidden elastic recovery); the
# diagnosis is told nothing of it.

# %%
machine = CONFIG / "hammer-lg1000.machine.toml"
steel = CONFIG / "steel-16NiCrMo13.process.toml"
sets = {}
for name, v0, seed in (("calib", "4.0,4.5,5.0,5.3,5.3", "3"), ("holdout", "4.2,4.8,5.1,5.3,5.3", "4")):
    sets[name] = out / name
    if not (sets[name] / "blow_01.csv").exists():
        subprocess.run([BIN, "simulate", "--machine", machine, "--process", steel, "--v0", v0, "--effect", "elastic_recovery:k_contact_N_per_m=1.5e9", "--captures", sets[name], "--capture-seed", seed], check=True, capture_output=True)
report = forgemon.diagnose(forgemon.Machine.from_toml(machine), sets["calib"], sets["holdout"], out=out / "diagnosis")
verdict = report["verdict"]
print("verdict:", verdict["effect"])
print("report:", out / "diagnosis" / "report.html")
