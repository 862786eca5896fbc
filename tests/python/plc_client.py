#!/usr/bin/env python3
"""Read forgemon's PLC result image (docs/interfaces.md §8) as a PLC would, with pymodbus.

The independent client of issue 19 §2: it polls holding registers 0-21 of unit 1 while a
`forgemon demo --plc ADDR` runs, keeps every image it saw twice in a row (so a half-updated
one is never kept), checks that writes and other addresses are refused with Modbus
exceptions, and once the alert-latched bit is set writes coil 0 (acknowledge), then coil 1
(new billet), keeping the registers before and after each. It sends one connection of
garbage bytes first, which the server must survive. It prints one JSON object for
tests/plc_server.rs to compare with the demo's recording; it decodes nothing with forgemon.

Usage: python3 tests/python/plc_client.py HOST:PORT SECONDS
Exit codes: 0 ok, 2 usage, 3 pymodbus missing, 1 anything else.
"""

import inspect
import json
import socket
import sys
import time

try:
    from pymodbus.client import ModbusTcpClient
except ImportError as err:  # pragma: no cover - depends on the machine
    print(f"plc_client.py: {err}; install it with: python3 -m pip install pymodbus", file=sys.stderr)
    sys.exit(3)

UNIT = 1
WORDS = 22
ALERT_LATCHED = 1 << 2


def unit_kw(method):
    """pymodbus 3.10+ names the unit `device_id`, earlier 3.x `slave`."""
    params = inspect.signature(method).parameters
    return "device_id" if "device_id" in params else "slave"


def error_code(result):
    """The Modbus exception code of a refused request, or None when it was answered."""
    return result.exception_code if result.isError() else None


def settle(read, done):
    """The registers once `done` holds of them, or after 1 s: the service takes a coil's
    command on its next turn, and the image follows the event that command publishes."""
    until = time.monotonic() + 1.0
    regs = read()
    while not done(regs) and time.monotonic() < until:
        time.sleep(0.01)
        regs = read()
    return regs


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    host, port = sys.argv[1].rsplit(":", 1)
    port, seconds = int(port), float(sys.argv[2])
    deadline = time.monotonic() + seconds

    # A client that sends garbage and hangs up: the server drops it and goes on.
    while True:
        try:
            with socket.create_connection((host, port), timeout=1.0) as s:
                s.sendall(b"\x00\x01\xff\xff\x00\x03garbage, not Modbus\r\n")
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)

    client = ModbusTcpClient(host, port=port, timeout=1.0, retries=0)
    if not client.connect():
        raise SystemExit(f"cannot connect to {host}:{port}")
    kw = {unit_kw(client.read_holding_registers): UNIT}

    def read():
        r = client.read_holding_registers(0, count=WORDS, **kw)
        if r.isError():
            raise RuntimeError(f"read refused: {r}")
        return list(r.registers)

    refused = {
        "write_register": error_code(client.write_register(7, 1, **kw)),
        "write_registers": error_code(client.write_registers(0, [1, 2], **kw)),
        "read_past_end": error_code(client.read_holding_registers(21, count=2, **kw)),
        "read_input": error_code(client.read_input_registers(0, count=2, **kw)),
        "write_coil_2": error_code(client.write_coil(2, True, **kw)),
        "read_coils": error_code(client.read_coils(0, count=2, **kw)),
        "other_unit": error_code(client.read_holding_registers(0, count=2, **{unit_kw(client.read_holding_registers): 2})),
    }

    images, heartbeats = [], []
    ack, billet = None, None
    previous = None
    start = time.monotonic()
    while time.monotonic() < deadline:
        try:
            regs = read()
        except Exception:  # the demo has stopped: its server is gone
            break
        now = time.monotonic() - start
        heartbeats.append([now, regs[0]])
        # Kept when the same image (heartbeat aside) is read twice in a row.
        if previous is not None and previous[1:] == regs[1:] and (not images or images[-1][1:] != regs[1:]):
            images.append(regs)
        previous = regs
        if ack is None and regs[1] & ALERT_LATCHED:
            ok = error_code(client.write_coil(0, True, **kw)) is None
            after = settle(read, lambda w: not w[1] & ALERT_LATCHED)
            ack = {"written": ok, "before": regs, "after": after, "images_before": len(images)}
        elif ack is not None and billet is None:
            before = regs
            ok = error_code(client.write_coil(1, True, **kw)) is None
            after = settle(read, lambda w: w[4:6] != before[4:6])
            billet = {"written": ok, "before": before, "after": after}
        time.sleep(0.01)
    client.close()
    json.dump(
        {"refused": refused, "images": images, "heartbeats": heartbeats, "ack": ack, "billet": billet},
        sys.stdout,
    )


if __name__ == "__main__":
    main()
