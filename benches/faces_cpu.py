#!/usr/bin/env python3
"""What the operator's screen and the plant's interfaces cost the service (issue 19: at most
2 % of a core more than without them, at 3 x 100 kHz, with one dashboard and one Foxglove
client connected). An end-to-end benchmark, not a test: it prints, it asserts nothing.

Runs `forgemon demo` in real time (one DAQ source, 3 channels at 100 kHz, a blow every
INTERVAL s) alternately
  - bare: no front end configured, no client;
  - faces: --http, --foxglove and --plc configured, the dashboard open in headless Chromium
    (the page, its event stream and its fetches), a Foxglove client subscribed to the results
    and the samples (tests/python/foxglove_client.py), and a PLC client reading the 20
    registers ten times a second (pymodbus);
and reports the demo process's CPU time (user + system, from the kernel's accounting of the
child) over its wall time. The simulated device runs inside the demo process in both, so the
difference is the front ends' cost.

Usage: faces_cpu.py FORGEMON_BINARY [RUNS] [BILLETS] [INTERVAL_S]
"""

import os
import resource
import socket
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
FOX = os.path.join(HERE, "..", "tests", "python", "foxglove_client.py")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def plc_poller(port, stop):
    try:
        from pymodbus.client import ModbusTcpClient
    except ImportError:
        return
    c = ModbusTcpClient("127.0.0.1", port=port)
    while not stop.is_set():
        try:
            if c.connect():
                c.read_holding_registers(0, count=20, device_id=1)
        except Exception:
            pass
        time.sleep(0.1)
    c.close()


def one_run(binary, faces, billets, interval):
    with tempfile.TemporaryDirectory() as d:
        args = [binary, "demo", "--billets", str(billets), "--interval", str(interval), "--dir", d]
        clients = []
        stop = threading.Event()
        if faces:
            http, fox, plc = free_port(), free_port(), free_port()
            args += ["--http", f"127.0.0.1:{http}", "--foxglove", f"127.0.0.1:{fox}", "--plc", f"127.0.0.1:{plc}"]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.monotonic()
        demo = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        if faces:
            # Wait for the service to listen, then connect the clients.
            for line in demo.stdout:
                if "dashboard on" in line:
                    break
            time.sleep(0.3)
            clients.append(subprocess.Popen(
                ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--remote-debugging-port=0",
                 f"http://127.0.0.1:{http}/"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            clients.append(subprocess.Popen(
                [sys.executable, FOX, f"ws://127.0.0.1:{fox}", "100000", str(billets * 8 * interval + 30)],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            threading.Thread(target=plc_poller, args=(plc, stop), daemon=True).start()
        demo.stdout.read()
        demo.wait()
        wall = time.monotonic() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        stop.set()
        for c in clients:
            c.kill()
            c.wait()
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        return cpu, wall


def main():
    binary = sys.argv[1]
    runs = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    billets = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    interval = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
    result = {False: [], True: []}
    for i in range(runs):
        for faces in (False, True):
            cpu, wall = one_run(binary, faces, billets, interval)
            share = 100.0 * cpu / wall
            result[faces].append(share)
            print(f"run {i + 1} {'faces' if faces else 'bare '}: {cpu:.2f} s CPU over {wall:.1f} s = {share:.2f} % of a core",
                  flush=True)
    mean = {k: sum(v) / len(v) for k, v in result.items()}
    diffs = [f - b for b, f in zip(result[False], result[True])]
    print(f"bare {mean[False]:.2f} %, faces {mean[True]:.2f} %: +{mean[True] - mean[False]:.2f} % of a core "
          f"(pairs {min(diffs):+.2f} to {max(diffs):+.2f}); load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
