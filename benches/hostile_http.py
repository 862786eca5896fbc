#!/usr/bin/env python3
"""What hostile clients cost the service (issue 39: while 1100 unauthenticated connections
are held open, half-sent or trickling, under a 1024 descriptor limit, /status with the token
answers at least 90 % of polls and the server closes every one of them within 45 s; RSS with
200 Foxglove attempts). An end-to-end benchmark, not a test: it prints, it asserts nothing.

Starts `forgemon run` (a token, [foxglove] on, every limit at its default, one serial source
on a tty that does not exist, so the service serves and waits) under `prlimit --nofile=1024`
when prlimit is there, then

  - http: holds CONNECTIONS connections without the token to the HTTP server for HOLD_S
    seconds, a third each idle (nothing sent), half-sent (a request line and a header) and
    trickling (one byte of a head every second), reopening each one the server closes;
    meanwhile polls GET /status with the token every 100 ms (a new connection each, 2 s to
    answer). Then stops reopening and waits until the server closed every one (90 s at
    most).
  - foxglove: 200 connections opened at once, each sending the WebSocket handshake, held
    10 s; the answers counted (101, 503, closed).

and reports the polls answered, the longest any hostile connection stayed open, the time
from the last reopening until all were closed, and the service's RSS and CPU in each phase.

Usage: hostile_http.py FORGEMON_BINARY [CONNECTIONS] [HOLD_S]
"""

import os
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
MACHINE = os.path.join(HERE, "..", "config", "hammer-lg1000.machine.toml")
TOKEN = "bench-hostile-http-token-0123"
HALF = b"GET /status HTTP/1.1\r\nhost: localhost\r\n"
UPGRADE = (b"GET / HTTP/1.1\r\nhost: 127.0.0.1\r\nupgrade: websocket\r\nconnection: Upgrade\r\n"
           b"sec-websocket-key: dGhlIHNhbXBsZSBub25jZQ==\r\nsec-websocket-version: 13\r\n"
           b"sec-websocket-protocol: foxglove.websocket.v1\r\n\r\n")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def config(d, http, fox):
    token = os.path.join(d, "token")
    with open(token, "w") as f:
        f.write(TOKEN)
    os.chmod(token, 0o600)
    text = f"""machine = "{os.path.abspath(MACHINE)}"
[recording]
dir = "rec"
[http]
listen = "127.0.0.1:{http}"
token_file = "token"
[foxglove]
listen = "127.0.0.1:{fox}"
[[sources]]
name = "daq"
kind = "serial"
path = "{d}/no-such-tty"
[[sources.channels]]
role = "load_N"
gain = 1.0
[[sources.channels]]
role = "disp_m"
gain = 1.0
[[sources.channels]]
role = "acc_mps2"
gain = 1.0
"""
    path = os.path.join(d, "service.toml")
    with open(path, "w") as f:
        f.write(text)
    return path


def poll_status(port):
    """Whether GET /status with the token was answered 200 within 2 s."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=2) as s:
            s.settimeout(2)
            s.sendall(f"GET /status HTTP/1.1\r\nhost: x\r\nauthorization: Bearer {TOKEN}\r\n"
                      "connection: close\r\n\r\n".encode())
            got = b""
            while True:
                chunk = s.recv(65536)
                if not chunk:
                    break
                got += chunk
            return got.startswith(b"HTTP/1.1 200")
    except OSError:
        return False


class Proc:
    """The service's RSS (kB) and CPU time (s), from /proc."""

    def __init__(self, pid):
        self.pid = pid
        self.tick = os.sysconf("SC_CLK_TCK")

    def rss_kb(self):
        with open(f"/proc/{self.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        return 0

    def cpu_s(self):
        with open(f"/proc/{self.pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / self.tick


class Hostile:
    """CONNECTIONS connections without the token, each idle, half-sent or trickling."""

    def __init__(self, port, n):
        self.port, self.n = port, n
        self.socks = [None] * n
        self.opened_at = [0.0] * n
        self.longest = 0.0
        self.opened = 0

    def open(self, i):
        try:
            s = socket.create_connection(("127.0.0.1", self.port), timeout=2)
            if i % 3 == 1:
                s.sendall(HALF)
            s.setblocking(False)
        except OSError:
            return
        self.socks[i], self.opened_at[i] = s, time.monotonic()
        self.opened += 1

    def reap(self, now):
        """Forget the sockets the server closed; how many are open."""
        for i, s in enumerate(self.socks):
            if s is None:
                continue
            try:
                closed = s.recv(4096) == b""
            except BlockingIOError:
                closed = False
            except OSError:
                closed = True
            if closed:
                self.longest = max(self.longest, now - self.opened_at[i])
                s.close()
                self.socks[i] = None
        return sum(s is not None for s in self.socks)

    def trickle(self, k):
        for i in range(2, self.n, 3):
            s = self.socks[i]
            if s is not None:
                try:
                    s.send(HALF[k % len(HALF):k % len(HALF) + 1])
                except OSError:
                    pass


def http_phase(port, proc, n, hold_s):
    h = Hostile(port, n)
    polls, answered, stop = [0], [0], threading.Event()

    def poller():
        while not stop.is_set():
            polls[0] += 1
            answered[0] += poll_status(port)
            time.sleep(0.1)

    cpu0, t0, rss = proc.cpu_s(), time.monotonic(), proc.rss_kb()
    t = threading.Thread(target=poller)
    t.start()
    k = 0
    while time.monotonic() - t0 < hold_s:
        now = time.monotonic()
        h.reap(now)
        for i in range(n):
            if h.socks[i] is None:
                h.open(i)
        h.trickle(k)
        k += 1
        rss = max(rss, proc.rss_kb())
        time.sleep(max(0.0, 1.0 - (time.monotonic() - now)))
    stop.set()
    t.join()
    cpu = proc.cpu_s() - cpu0
    wall = time.monotonic() - t0
    last_open = time.monotonic()
    left = h.reap(last_open)
    while left and time.monotonic() - last_open < 90:
        time.sleep(0.1)
        left = h.reap(time.monotonic())
    all_closed = time.monotonic() - last_open
    # Those still open count with their age so far.
    now = time.monotonic()
    for i, s in enumerate(h.socks):
        if s is not None:
            h.longest = max(h.longest, now - h.opened_at[i])
    return {"polls": polls[0], "answered": answered[0], "opened": h.opened, "longest_s": h.longest,
            "left": left, "all_closed_s": all_closed, "rss_kb": rss, "cpu": 100 * cpu / wall}


def answer(s):
    s.settimeout(10)
    head = b""
    try:
        while b"\r\n\r\n" not in head:
            chunk = s.recv(4096)
            if not chunk:
                return "closed"
            head += chunk
    except OSError:
        return "closed"
    return head.split()[1].decode()


def foxglove_phase(port, proc, n=200, hold_s=10):
    rss0, cpu0, t0 = proc.rss_kb(), proc.cpu_s(), time.monotonic()
    socks = []
    for _ in range(n):
        try:
            socks.append(socket.create_connection(("127.0.0.1", port), timeout=2))
        except OSError:
            pass
    for s in socks:
        try:
            s.sendall(UPGRADE)
        except OSError:
            pass
    counts = {}
    for s in socks:
        a = answer(s)
        counts[a] = counts.get(a, 0) + 1
    rss = proc.rss_kb()
    while time.monotonic() - t0 < hold_s:
        time.sleep(0.5)
        rss = max(rss, proc.rss_kb())
    cpu = 100 * (proc.cpu_s() - cpu0) / (time.monotonic() - t0)
    for s in socks:
        s.close()
    return {"attempts": n, "answers": counts, "rss0_kb": rss0, "rss_kb": rss, "cpu": cpu}


def main():
    binary = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    hold_s = float(sys.argv[3]) if len(sys.argv) > 3 else 30.0
    hard = resource.getrlimit(resource.RLIMIT_NOFILE)[1]
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    with tempfile.TemporaryDirectory() as d:
        http, fox = free_port(), free_port()
        cmd = [binary, "run", "--config", config(d, http, fox)]
        limited = shutil.which("prlimit") is not None
        if limited:
            cmd = ["prlimit", "--nofile=1024:1024", "--"] + cmd
        svc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 20
            while not poll_status(http):
                if time.monotonic() > deadline or svc.poll() is not None:
                    sys.exit("the service did not come up")
                time.sleep(0.1)
            proc = Proc(svc.pid)
            time.sleep(2)
            idle_rss, c0 = proc.rss_kb(), proc.cpu_s()
            time.sleep(3)
            idle_cpu = 100 * (proc.cpu_s() - c0) / 3
            h = http_phase(http, proc, n, hold_s)
            time.sleep(2)
            f = foxglove_phase(fox, proc)
        finally:
            svc.terminate()
            svc.wait()
    limit = "1024 descriptors (prlimit)" if limited else "the shell's descriptor limit (no prlimit)"
    print(f"forgemon run, every limit at its default, under {limit}; load average {os.getloadavg()[0]:.1f}")
    print(f"{'phase':<34} {'result':<52} {'RSS MB':>7} {'CPU %':>6}")
    print(f"{'idle':<34} {'':<52} {idle_rss / 1024:7.1f} {idle_cpu:6.1f}")
    held = f"{n} held {hold_s:.0f} s"
    polled = f"/status: {h['answered']}/{h['polls']} = {100 * h['answered'] / max(1, h['polls']):.1f} % answered"
    print(f"{'http: ' + held:<34} {polled:<52} {h['rss_kb'] / 1024:7.1f} {h['cpu']:6.1f}")
    if h["left"]:
        end = f"{h['left']} still open {h['all_closed_s']:.0f} s after the last reopening"
    else:
        end = f"all closed {h['all_closed_s']:.1f} s after the last reopening"
    closed = f"{h['opened']} opened in all; longest open {h['longest_s']:.1f} s; {end}"
    print(f"{'':<34} {closed}")
    answers = ", ".join(f"{k}: {v}" for k, v in sorted(f["answers"].items()))
    answers += f" (RSS before {f['rss0_kb'] / 1024:.1f})"
    print(f"{'foxglove: 200 attempts at once':<34} {answers:<52} {f['rss_kb'] / 1024:7.1f} {f['cpu']:6.1f}")


if __name__ == "__main__":
    main()
