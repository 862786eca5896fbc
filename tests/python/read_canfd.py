#!/usr/bin/env python3
"""Decode a CAN FD `candump -L` log with the standard tools (python-can reads the lines,
cantools decodes each frame with the DBC) and print JSON: the frames' Seq values and every
sample as [load_N, disp_m, acc_mps2], sample 0 of each block first.
usage: read_canfd.py LOG DBC        Needs: python3 -m pip install python-can cantools
"""
import json
import sys

import can
import cantools

log, dbc = sys.argv[1], sys.argv[2]
msg = cantools.database.load_file(dbc).get_message_by_name("ForgeBlock")
seqs, samples = [], []
for frame in can.CanutilsLogReader(log):
    assert frame.is_fd and frame.arbitration_id == msg.frame_id, frame
    d = msg.decode(frame.data, scaling=True)
    seqs.append(d["Seq"])
    samples += [[d[f"Load_{k}"], d[f"Disp_{k}"], d[f"Acc_{k}"]] for k in range(8)]
print(json.dumps({"seq": seqs, "samples": samples}))
