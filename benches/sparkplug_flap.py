#!/usr/bin/env python3
"""Benchmark (issue 21 §3): one service publishing Sparkplug B at 2 blows per second while
the broker flaps (10 s up, 10 s down) for 10 minutes. Reports, does not assert:

- blows made (the demo's printed blow lines) against distinct blows published (DDATA the
  independent subscriber received, by blow time of contact), and what was left in the
  node's queue on disk when it stopped;
- the median end-to-end latency, from the moment the service made the result (the DDATA
  timestamp) to the subscriber's receipt, for blows published live and from the queue;
- the queue's high-water mark, measured from outside: the most blows made and not yet
  received at any instant (it includes the ones in flight).

usage: python3 benches/sparkplug_flap.py [--seconds 600] [--period 10]
       (build first: cargo build --release; needs mosquitto, paho-mqtt, protobuf,
        grpcio-tools, as .ci/run installs)
"""

import argparse
import json
import os
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FORGEMON = os.environ.get("FORGEMON_BIN", os.path.join(ROOT, "target", "release", "forgemon"))
SUBSCRIBER = os.path.join(ROOT, "tests", "python", "sparkplug_subscriber.py")
BLOWS_PER_BILLET = 8


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Broker:
    def __init__(self, tmp, port):
        self.port = port
        self.conf = os.path.join(tmp, "mosquitto.conf")
        with open(self.conf, "w") as f:
            f.write(f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\n"
                    f"persistence_location {tmp}/\nqueue_qos0_messages true\nmax_queued_messages 0\n"
                    "log_dest none\nuser root\n")
        self.proc = None

    def start(self):
        self.proc = subprocess.Popen(["mosquitto", "-c", self.conf],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        t0 = time.time()
        while time.time() - t0 < 10:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                return
            except OSError:
                time.sleep(0.02)
        raise RuntimeError("mosquitto did not listen")

    def stop(self):
        if self.proc:
            self.proc.terminate()
            self.proc.wait()
            self.proc = None


def queued_records(qdir):
    """Records still waiting in the node's queue on disk (from `queue.head` on)."""
    try:
        data = open(os.path.join(qdir, "queue.bin"), "rb").read()
    except OSError:
        return 0
    try:
        at = struct.unpack("<Q", open(os.path.join(qdir, "queue.head"), "rb").read())[0]
    except (OSError, struct.error):
        at = 0
    n = 0
    while at + 8 <= len(data):
        (length,) = struct.unpack("<I", data[at:at + 4])
        at += 8 + length
        n += 1
    return n


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=600)
    ap.add_argument("--period", type=float, default=10)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="spb_flap_")
    port = free_port()
    broker = Broker(tmp, port)
    broker.start()
    sub = subprocess.Popen([sys.executable, SUBSCRIBER, "127.0.0.1", str(port), "historian-bench",
                            str(args.seconds + 600), "0"],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    messages = []
    connected = threading.Event()

    def read_sub():
        for line in sub.stdout:
            v = json.loads(line)
            if v.get("event") == "connected":
                connected.set()
            messages.append(v)
    threading.Thread(target=read_sub, daemon=True).start()
    connected.wait(30)

    billets = int(args.seconds * 2 / BLOWS_PER_BILLET) + 1
    demo = subprocess.Popen([FORGEMON, "demo", "--billets", str(billets), "--interval", "0.5",
                             "--mqtt", f"mqtt://127.0.0.1:{port}", "--dir", os.path.join(tmp, "rec")],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    made = []

    def read_demo():
        for line in demo.stdout:
            w = line.split()
            if len(w) >= 2 and w[0].isdigit() and w[1].isdigit():
                made.append(int(w[0]))
    threading.Thread(target=read_demo, daemon=True).start()

    t0 = time.time()
    flaps = 0
    while time.time() - t0 < args.seconds:
        time.sleep(args.period)
        if broker.proc:
            broker.stop()
        else:
            broker.start()
        flaps += 1
    if not broker.proc:
        broker.start()
    # The broker stays up a last period so the node reconnects and drains its queue, then
    # SIGTERM: the service finishes its recording and flushes what is left.
    time.sleep(args.period)
    demo.terminate()
    demo.wait()
    left = queued_records(os.path.join(tmp, "rec", "sparkplug-queue"))
    time.sleep(5)
    sub.stdin.close()
    sub.wait()
    broker.stop()

    ddata = [m for m in messages if m.get("type") == "DDATA"]
    first_rx = {}
    live_lat, hist_lat = [], []
    for m in ddata:
        key = m["metrics"]["blow/t_contact_s"]["value"]
        if key in first_rx:
            continue
        first_rx[key] = (m["timestamp"], m["rx_ms"])
        lat = m["rx_ms"] - m["timestamp"]
        (hist_lat if m["metrics"]["blow/plastic_J"]["historical"] else live_lat).append(lat)
    # High water: blows made and not yet received, at each instant something happened.
    events = sorted([(t, 1) for t, _ in first_rx.values()] + [(r, -1) for _, r in first_rx.values()])
    level = high = 0
    for _, d in events:
        level += d
        high = max(high, level)
    births = sum(1 for m in messages if m.get("type") == "NBIRTH")
    print(json.dumps({
        "seconds": args.seconds,
        "flap_period_s": args.period,
        "broker_flaps": flaps,
        "births": births,
        "blows_made": len(made),
        "blows_published_distinct": len(first_rx),
        "ddata_received": len(ddata),
        "left_in_queue_on_disk": left,
        "median_latency_ms_all": statistics.median([r - t for t, r in first_rx.values()]) if first_rx else None,
        "median_latency_ms_live": statistics.median(live_lat) if live_lat else None,
        "median_latency_ms_from_queue": statistics.median(hist_lat) if hist_lat else None,
        "queue_high_water_blows": high,
    }, indent=1))


if __name__ == "__main__":
    main()
