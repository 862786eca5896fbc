#!/usr/bin/env python3
"""What hostile clients do to the PLC image and the OPC UA server (issue 39: every server has
limits; an unauthenticated client can never starve the others). An end-to-end benchmark,
not a test: it prints, it asserts nothing.

Runs `forgemon run` with `[plc_server]` and anonymous `[opcua]` on loopback, every limit at
its default (idle_timeout_s = 30, max_connections = 16, hello_timeout_s = 5), and
  - connects a well-behaved PLC (pymodbus) that reads the 20 registers ten times a second;
  - opens HOSTILE Modbus connections at once: 70 % idle (connect, send nothing), 20 %
    trickling (one byte of a request every 2 s, a request never completed), 10 % random
    bytes (sent once, then held), and OPCUA raw OPC UA connections that never send HEL;
  - 2 s into the flood, connects a second PLC, as one that restarts would.
It reports the share of each PLC's reads answered, when the last hostile connection of each
kind was closed by the server, and the service's resident memory before, at most and after.

Usage: hostile_modbus.py FORGEMON_BINARY [HOSTILE] [OPCUA] [SECONDS]
"""

import os
import random
import resource
import selectors
import socket
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rss_mb(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def service_toml(d, http, plc, opcua):
    machine = os.path.join(ROOT, "config", "hammer-lg1000.machine.toml")
    channels = "".join(f'[[sources.channels]]\nrole = "{r}"\ngain = 1.0\n' for r in ("load_N", "disp_m", "acc_mps2"))
    text = (
        f'machine = "{machine}"\n[recording]\ndir = "rec"\n[http]\nlisten = "127.0.0.1:{http}"\n'
        f'[plc_server]\nlisten = "127.0.0.1:{plc}"\n[opcua]\nlisten = "opc.tcp://127.0.0.1:{opcua}"\n'
        f'[[sources]]\nname = "daq"\nkind = "serial"\npath = "{d}/no-such-tty"\n{channels}'
    )
    path = os.path.join(d, "service.toml")
    with open(path, "w") as f:
        f.write(text)
    return path


def plc_poller(port, stop, tally, start_after):
    """Read the image every 0.1 s; count reads tried and answered."""
    from pymodbus.client import ModbusTcpClient
    time.sleep(start_after)
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=1.0, retries=0)
    while not stop.is_set():
        tally["tried"] += 1
        try:
            if c.connected or c.connect():
                r = c.read_holding_registers(0, count=20, device_id=1)
                if not r.isError() and len(r.registers) == 20:
                    tally["answered"] += 1
        except Exception:
            c.close()
        time.sleep(0.1)
    c.close()


def open_hostile(plc, opcua, n, n_opcua):
    """The hostile connections: (socket, kind)."""
    out = []
    kinds = ["idle"] * (n * 7 // 10) + ["trickle"] * (n * 2 // 10)
    kinds += ["random"] * (n - len(kinds))
    for kind in kinds:
        s = socket.create_connection(("127.0.0.1", plc))
        if kind == "random":
            s.sendall(random.randbytes(64))
        out.append((s, kind))
    for _ in range(n_opcua):
        out.append((socket.create_connection(("127.0.0.1", opcua)), "opcua_no_hel"))
    for s, _ in out:
        s.setblocking(False)
    return out


# A request that never completes: MBAP length 254 announces 253 bytes of PDU.
TRICKLE = bytes([0, 1, 0, 0, 0, 254, 1, 3]) + bytes(252)


def watch(hostile, t0, seconds):
    """Until every hostile connection is closed or `seconds` pass: when each kind's last
    one was closed (None: some still open), and the peak RSS seen."""
    sel = selectors.DefaultSelector()
    for i, (s, kind) in enumerate(hostile):
        sel.register(s, selectors.EVENT_READ, (i, kind))
    closed_at, sent = {}, {}
    next_trickle = t0
    while sel.get_map() and time.monotonic() - t0 < seconds:
        for key, _ in sel.select(timeout=0.2):
            i, kind = key.data
            try:
                data = key.fileobj.recv(4096)
            except (ConnectionError, OSError):
                data = b""
            if not data:
                sel.unregister(key.fileobj)
                key.fileobj.close()
                closed_at[i] = time.monotonic() - t0
        if time.monotonic() >= next_trickle:
            next_trickle += 2.0
            for i, (s, kind) in enumerate(hostile):
                if kind == "trickle" and i not in closed_at:
                    k = sent.get(i, 0)
                    try:
                        s.send(TRICKLE[k:k + 1])
                        sent[i] = k + 1
                    except OSError:
                        pass
    last = {}
    for i, (s, kind) in enumerate(hostile):
        if i not in closed_at:
            last[kind] = None
            s.close()
        elif last.get(kind, 0) is not None:
            last[kind] = max(last.get(kind, 0), closed_at[i])
    return last


def main():
    if len(sys.argv) < 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    binary = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    n_opcua = int(sys.argv[3]) if len(sys.argv) > 3 else 50
    seconds = float(sys.argv[4]) if len(sys.argv) > 4 else 60.0
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, min(hard, 4 * n + 256)), hard))
    with tempfile.TemporaryDirectory() as d:
        http, plc, opcua = free_port(), free_port(), free_port()
        svc = subprocess.Popen([binary, "run", "--config", service_toml(d, http, plc, opcua)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 15
            while True:
                try:
                    socket.create_connection(("127.0.0.1", plc)).close()
                    socket.create_connection(("127.0.0.1", opcua)).close()
                    break
                except OSError:
                    if time.monotonic() > deadline:
                        raise SystemExit("the service did not come up")
                    time.sleep(0.1)
            time.sleep(1.0)
            rss_before = rss_mb(svc.pid)
            stop = threading.Event()
            first, second = {"tried": 0, "answered": 0}, {"tried": 0, "answered": 0}
            threads = [threading.Thread(target=plc_poller, args=(plc, stop, first, 0.0), daemon=True)]
            threads[0].start()
            time.sleep(1.0)
            t0 = time.monotonic()
            hostile = open_hostile(plc, opcua, n, n_opcua)
            opened_s = time.monotonic() - t0
            threads.append(threading.Thread(target=plc_poller, args=(plc, stop, second, 2.0), daemon=True))
            threads[1].start()
            peak = [rss_before]

            def sample():
                while not stop.is_set():
                    peak[0] = max(peak[0], rss_mb(svc.pid))
                    time.sleep(0.2)

            threading.Thread(target=sample, daemon=True).start()
            last = watch(hostile, t0, seconds)
            stop.set()
            for t in threads:
                t.join()
            rss_after = rss_mb(svc.pid)
        finally:
            svc.terminate()
            svc.wait()
    print(f"hostile connections: {n} Modbus ({n * 7 // 10} idle, {n * 2 // 10} trickling, "
          f"{n - n * 7 // 10 - n * 2 // 10} random bytes) + {n_opcua} OPC UA without HEL, opened in {opened_s:.2f} s")
    for name, t in (("PLC connected before", first), ("PLC connecting 2 s in", second)):
        share = 100.0 * t["answered"] / t["tried"] if t["tried"] else float("nan")
        print(f"{name:24s} reads answered {t['answered']}/{t['tried']} = {share:.1f} %")
    for kind in ("idle", "trickle", "random", "opcua_no_hel"):
        t = last.get(kind)
        print(f"last {kind:14s} closed by the server after " + ("NOT CLOSED" if t is None else f"{t:.1f} s"))
    print(f"service RSS: before {rss_before:.1f} MB, peak {peak[0]:.1f} MB, after {rss_after:.1f} MB")


if __name__ == "__main__":
    main()
