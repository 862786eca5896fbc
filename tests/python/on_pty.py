"""Run a command with its stdout and stderr on a pty, as on a terminal (tests/cli_first_hour.rs).

usage: on_pty.py TIMEOUT_S MARKER [SIGNAL] -- COMMAND...

Echoes what the command prints. Once a line holds MARKER (or after TIMEOUT_S), it fetches
the first http:// URL of that line and prints `GET <status>` (or `GET failed: why`), waits
a second, prints `running <yes|no>`, sends SIGNAL (INT unless named: HUP, TERM) and prints `exit <status>` when the
command has ended (`exit timeout` if it has not within TIMEOUT_S more). Standard library only.
"""

import os
import pty
import re
import select
import signal
import subprocess
import sys
import time
import urllib.request


def read_some(fd, out, wait_s):
    """Append what the pty gives within wait_s to out; False at its end."""
    ready, _, _ = select.select([fd], [], [], wait_s)
    if not ready:
        return True
    try:
        data = os.read(fd, 4096)
    except OSError:
        return False
    if not data:
        return False
    out.extend(data)
    return True


def main():
    timeout_s, marker = float(sys.argv[1]), sys.argv[2]
    dash = sys.argv.index("--")
    signum = getattr(signal, "SIG" + sys.argv[3]) if dash > 3 else signal.SIGINT
    cmd = sys.argv[dash + 1:]
    master, slave = pty.openpty()
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, close_fds=True)
    os.close(slave)
    out = bytearray()
    deadline = time.monotonic() + timeout_s
    line = None
    while time.monotonic() < deadline and line is None:
        if not read_some(master, out, 0.1):
            break
        for l in out.decode("utf-8", "replace").splitlines():
            if marker in l:
                line = l
    if line is not None:
        url = re.search(r"http://\S+", line)
        try:
            status = urllib.request.urlopen(url.group(0), timeout=5).status if url else "no url"
            print(f"GET {status}")
        except Exception as e:  # noqa: BLE001 - the test reads the reason
            print(f"GET failed: {e}")
        end = time.monotonic() + 1.0
        while time.monotonic() < end and read_some(master, out, 0.1):
            pass
    print(f"running {'yes' if proc.poll() is None else 'no'}")
    if proc.poll() is None:
        proc.send_signal(signum)
    try:
        code = proc.wait(timeout=timeout_s)
        print(f"exit {code}")
    except subprocess.TimeoutExpired:
        proc.kill()
        print("exit timeout")
    while read_some(master, out, 0.2):
        pass
    print("--- output")
    print(out.decode("utf-8", "replace"))


main()
