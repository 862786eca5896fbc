#!/usr/bin/env python3
"""What the always-on service costs a plant's PC (issue 42: at most 5 % of one core, with
memory flat, over 10 minutes). An end-to-end benchmark, not a test: it prints, it asserts
nothing.

`forgemon simulate-device` drives a real pty in another process: a hammer at 3 channels x
100 kHz in the binary framing, a blow every INTERVAL s, billets without end. `forgemon run`
reads that pty with a service file of its own: recording to MCAP, the HTTP dashboard, the
PLC result image and Foxglove, each with one client:
  - the dashboard open in headless Chromium (the page, its event stream and its fetches);
  - a Foxglove client subscribed to the results and the samples
    (tests/python/foxglove_client.py, `websockets`);
  - a PLC client reading the 20 result registers ten times a second (`pymodbus`).

Every SAMPLE_S it reads the service's CPU time (user + system) and resident memory from
/proc/PID, and prints the share of one core over that span. At the end: the share over the
whole run after the first minute (start-up excluded), its range over the spans, RSS after
the first minute against RSS at the end, and the blows the service reported.

Usage: live_cost.py FORGEMON_BINARY [DURATION_S=600] [INTERVAL_S=1.0] [SAMPLE_S=30]
Needs chromium, websockets and pymodbus (`bash .ci/run` installs them into target/ci-venv:
run it with target/ci-venv/bin/python3). A client that cannot start is said, not hidden.
"""

import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
FOX = os.path.join(ROOT, "tests", "python", "foxglove_client.py")
MACHINE = os.path.abspath(os.path.join(ROOT, "config", "hammer-lg1000.machine.toml"))
PROCESS = os.path.abspath(os.path.join(ROOT, "config", "steel-16NiCrMo13.process.toml"))
TICK = os.sysconf("SC_CLK_TCK")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_s(pid):
    """User + system CPU seconds of the process (fields 14 and 15 of /proc/PID/stat)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def rss_mb(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def status(http):
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{http}/status", timeout=2) as r:
            return json.load(r)
    except Exception:
        return None


def plc_poller(port, stop, said):
    try:
        from pymodbus.client import ModbusTcpClient
    except ImportError:
        said.append("PLC client not started: pymodbus missing")
        return
    c = ModbusTcpClient("127.0.0.1", port=port)
    reads = 0
    while not stop.is_set():
        try:
            if c.connect() and not c.read_holding_registers(0, count=20, device_id=1).isError():
                reads += 1
        except Exception:
            pass
        time.sleep(0.1)
    c.close()
    said.append(f"PLC client: {reads} reads of 20 registers")


def service_toml(d, pty, http, fox, plc):
    return f"""machine = "{MACHINE}"
process = "{PROCESS}"
[recording]
dir = "{d}/rec"
[http]
listen = "127.0.0.1:{http}"
[foxglove]
listen = "127.0.0.1:{fox}"
[plc_server]
listen = "127.0.0.1:{plc}"
[[sources]]
name = "daq"
kind = "serial"
path = "{pty}"
baud = 921600
format = "binary"
[[sources.channels]]
role = "load_N"
gain = 1.0
[[sources.channels]]
role = "disp_m"
gain = 1e-6
[[sources.channels]]
role = "acc_mps2"
gain = 1e-3
"""


def main():
    binary = os.path.abspath(sys.argv[1])
    duration = float(sys.argv[2]) if len(sys.argv) > 2 else 600.0
    interval = sys.argv[3] if len(sys.argv) > 3 else "1.0"
    sample_s = float(sys.argv[4]) if len(sys.argv) > 4 else 30.0
    procs, stop, said = [], threading.Event(), []
    with tempfile.TemporaryDirectory() as d:
        try:
            device = subprocess.Popen(
                [binary, "simulate-device", "--machine", MACHINE, "--process", PROCESS,
                 "--v0", "3.9,5.3,5.3,5.3,5.3,5.3,5.3,5.3", "--interval", interval],
                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            procs.append(device)
            line = device.stdout.readline()
            pty = re.search(r"(/dev/pts/\d+)", line).group(1)
            http, fox, plc = free_port(), free_port(), free_port()
            cfg = os.path.join(d, "service.toml")
            with open(cfg, "w") as f:
                f.write(service_toml(d, pty, http, fox, plc))
            run = subprocess.Popen([binary, "run", "--config", cfg],
                                   stdout=subprocess.DEVNULL, stderr=open(os.path.join(d, "run.log"), "w"))
            procs.append(run)
            for _ in range(100):
                if status(http) is not None:
                    break
                time.sleep(0.1)
            else:
                sys.exit(f"forgemon run did not answer /status: {open(os.path.join(d, 'run.log')).read()[-2000:]}")
            procs.append(subprocess.Popen(
                ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--remote-debugging-port=0",
                 f"http://127.0.0.1:{http}/"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            procs.append(subprocess.Popen(
                [sys.executable, FOX, f"ws://127.0.0.1:{fox}", "1000000000", str(duration + 60)],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            threading.Thread(target=plc_poller, args=(plc, stop, said), daemon=True).start()

            t0, c0 = time.monotonic(), cpu_s(run.pid)
            marks = [(t0, c0, rss_mb(run.pid))]
            print(f"forgemon run (pid {run.pid}) on {pty}, a blow every {interval} s; dashboard, PLC and "
                  f"Foxglove with one client each; {duration:.0f} s, sampled every {sample_s:.0f} s", flush=True)
            while time.monotonic() - t0 < duration:
                time.sleep(min(sample_s, duration - (time.monotonic() - t0)))
                if run.poll() is not None:
                    sys.exit(f"forgemon run ended early: {open(os.path.join(d, 'run.log')).read()[-2000:]}")
                t, c, r = time.monotonic(), cpu_s(run.pid), rss_mb(run.pid)
                tp, cp, _ = marks[-1]
                marks.append((t, c, r))
                print(f"  {t - t0:6.0f} s: {100 * (c - cp) / (t - tp):5.2f} % of a core, RSS {r:6.1f} MB", flush=True)
            st = status(http)
            for name, p in (("dashboard (Chromium)", procs[2]), ("Foxglove client", procs[3])):
                code = p.poll()
                said.append(f"{name}: " + ("still connected at the end" if code is None else f"ended early, exit {code}"))
        finally:
            stop.set()
            for p in reversed(procs):
                p.terminate()
            for p in procs:
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
        # After the first minute: start-up (config, model, first allocations) excluded.
        warm = next((i for i, m in enumerate(marks) if m[0] - marks[0][0] >= 60), 0)
        (tw, cw, rw), (te, ce, re_) = marks[warm], marks[-1]
        spans = [100 * (b[1] - a[1]) / (b[0] - a[0]) for a, b in zip(marks[warm:], marks[warm + 1:])]
        rec = os.path.join(d, "rec")
        size = sum(os.path.getsize(os.path.join(rec, f)) for f in os.listdir(rec)) if os.path.isdir(rec) else 0
        for s in said:
            print(f"  {s}")
        st = st or {}
        print(f"service: {st.get('samples')} samples, {st.get('blows')} blows ({st.get('incomplete_blows')} incomplete, "
              f"{st.get('implausible_blows')} implausible); recorded {size / 1e6:.0f} MB")
        if spans:
            line = (f"live cost after the first minute: {100 * (ce - cw) / (te - tw):.2f} % of one core over "
                    f"{te - tw:.0f} s (spans of {sample_s:.0f} s: {min(spans):.2f} to {max(spans):.2f} %); "
                    f"RSS {rw:.1f} MB at {tw - marks[0][0]:.0f} s, {re_:.1f} MB at the end "
                    f"(max {max(m[2] for m in marks[warm:]):.1f}); load average {os.getloadavg()[0]:.1f}")
            print(line)
            # For the performance report (`cargo bench --bench headline` puts it in).
            out = os.path.join(ROOT, "target", "bench-data", "live_cost.txt")
            os.makedirs(os.path.dirname(out), exist_ok=True)
            with open(out, "w") as f:
                f.write(f"{time.strftime('%Y-%m-%d', time.gmtime())}, {duration:.0f} s, a blow every {interval} s, "
                        f"{st.get('blows')} blows: {line}\n")


if __name__ == "__main__":
    main()
