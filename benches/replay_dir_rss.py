#!/usr/bin/env python3
"""Memory of `forgemon replay DIR` over a day-sized rotated run (issue 42: memory flat). An
end-to-end benchmark, not a test: it prints, it asserts nothing.

Makes the recording once with `forgemon demo --fast --billets BILLETS` (1000 billets: 8000
blows, 1.2 G samples, about 10 GB in 512 MiB files, some 4 minutes on 2 cores) in
target/bench-data/demo-BILLETS, then replays the directory with --json into /dev/null,
reading its resident memory from /proc every half second. Prints the wall and CPU time,
the peak RSS (from the kernel's accounting of the child), and RSS over the run.

Usage: replay_dir_rss.py FORGEMON_BINARY [BILLETS=1000]. Standard library only.
"""

import glob
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    binary = os.path.abspath(sys.argv[1])
    billets = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    d = os.path.join(HERE, "..", "target", "bench-data", f"demo-{billets}")
    if not glob.glob(os.path.join(d, "*.mcap")):
        print(f"making the demo recording of {billets} billets in {d} ...", flush=True)
        subprocess.run([binary, "demo", "--fast", "--billets", str(billets), "--dir", d],
                       stdout=subprocess.DEVNULL, check=True)
    files = sorted(glob.glob(os.path.join(d, "*.mcap")))
    size = sum(os.path.getsize(f) for f in files)
    t0 = time.monotonic()
    p = subprocess.Popen([binary, "replay", d, "--json"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    samples = []
    while True:
        pid, status, usage = os.wait4(p.pid, os.WNOHANG)
        if pid:
            break
        try:
            with open(f"/proc/{p.pid}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        samples.append((time.monotonic() - t0, int(line.split()[1]) / 1024))
        except FileNotFoundError:
            pass
        time.sleep(0.5)
    wall = time.monotonic() - t0
    said = p.stderr.read().decode(errors="replace").strip().splitlines()
    print(f"replay of {len(files)} files, {size / 1e9:.1f} GB: {wall:.1f} s wall, "
          f"{usage.ru_utime + usage.ru_stime:.1f} s CPU, exit {os.waitstatus_to_exitcode(status)}; "
          f"{said[-1] if said else ''}")
    n = len(samples)
    if n:
        for q in (0, n // 4, n // 2, 3 * n // 4, n - 1):
            print(f"  t = {samples[q][0]:5.1f} s: RSS {samples[q][1]:6.1f} MB")
        rest = [r for _, r in samples[n // 10:]]
        print(f"peak RSS {usage.ru_maxrss / 1024:.1f} MB; after the first tenth of the run RSS stays within "
              f"{min(rest):.1f} to {max(rest):.1f} MB")


if __name__ == "__main__":
    main()
