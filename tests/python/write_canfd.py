#!/usr/bin/env python3
"""Write a CAN FD `candump -L` log of samples with the standard tools, not forgemon's code:
cantools encodes each block of 8 samples with the DBC (config/hammer-canfd.dbc), python-can's
CanutilsLogWriter writes the lines. tests/acquire_canfd.rs decodes the result with forgemon.

usage: write_canfd.py ROWS.csv DBC OUT.log [--drop-frame K ...] [--bad-line K ...]

ROWS.csv has the header t_s,load_N,disp_m,acc_mps2 (docs/interfaces.md §1). A block is
stamped with its last sample's time; Seq is the index of its first sample. --drop-frame K
leaves out frame K (0-based); --bad-line K replaces line K (1-based) of the log by a
malformed line (an odd number of hex digits).
Needs: python3 -m pip install python-can cantools
"""
import argparse
import csv

import can
import cantools

BLOCK = 8

ap = argparse.ArgumentParser()
ap.add_argument("rows")
ap.add_argument("dbc")
ap.add_argument("out")
ap.add_argument("--drop-frame", type=int, action="append", default=[])
ap.add_argument("--bad-line", type=int, action="append", default=[])
a = ap.parse_args()

db = cantools.database.load_file(a.dbc)
msg = db.get_message_by_name("ForgeBlock")
assert msg.is_fd and msg.length == 64, "ForgeBlock is a 64-byte CAN FD message"
with open(a.rows, newline="") as f:
    rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]

writer = can.CanutilsLogWriter(a.out, channel="can0")
for frame, first in enumerate(range(0, len(rows) - BLOCK + 1, BLOCK)):
    block = rows[first : first + BLOCK]
    values = {"Seq": first}
    for k, r in enumerate(block):
        values[f"Load_{k}"] = r["load_N"]
        values[f"Acc_{k}"] = r["acc_mps2"]
        values[f"Disp_{k}"] = r["disp_m"]
    if frame in a.drop_frame:
        continue
    data = msg.encode(values, scaling=True, strict=True)
    writer.on_message_received(
        can.Message(
            timestamp=block[-1]["t_s"],
            arbitration_id=msg.frame_id,
            is_extended_id=False,
            is_fd=True,
            bitrate_switch=True,
            data=data,
        )
    )
writer.stop()

if a.bad_line:
    with open(a.out) as f:
        lines = f.read().splitlines()
    for k in a.bad_line:
        stamp, rest = lines[k - 1].split(" ", 1)
        lines[k - 1] = f"{stamp} can0 121##1ABC"
    with open(a.out, "w") as f:
        f.write("\n".join(lines) + "\n")
