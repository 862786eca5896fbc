#!/usr/bin/env python3
"""Read forgemon's PLC result image (docs/interfaces.md §8) as a PLC would, with pymodbus.

The independent client of issue 19 §2: it polls holding registers 0-21 of unit 1 while a
`forgemon demo --plc ADDR` runs, keeps every image it saw twice in a row (so a half-updated
one is never kept), checks that writes and other addresses are refused with Modbus
exceptions, and once the alert-latched bit is set writes coil 0 (acknowledge), then coil 1
(new billet), keeping the registers before and after each. Then it writes the part block
(registers 100-147: part id, lot and die set as ASCII), reads it back, and writes coil 2 (a
new billet forged as the block says) and coil 3 (a die change), keeping the registers
around each. It sends one connection of
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
WORDS = 30
PART_BLOCK = 100
PART = {"part_id": "P-000418", "lot": "4711", "die_set": "18"}
ALERT_LATCHED = 1 << 2


def unit_kw(method):
    """pymodbus 3.10+ names the unit `device_id`, earlier 3.x `slave`."""
    params = inspect.signature(method).parameters
    return "device_id" if "device_id" in params else "slave"


def error_code(result):
    """The Modbus exception code of a refused request, or None when it was answered."""
    return result.exception_code if result.isError() else None


def ascii_words(text):
    """`text` as 16 registers, two characters each, the first in the high byte, NUL-padded."""
    raw = text.encode("ascii").ljust(32, b"\0")
    return [(raw[i] << 8) | raw[i + 1] for i in range(0, 32, 2)]


def part_step(client, kw, read):
    """Write the part block, read it back, then coil 2 and coil 3, with the registers around each."""
    words = sum((ascii_words(PART[k]) for k in ("part_id", "lot", "die_set")), [])
    wrote = error_code(client.write_registers(PART_BLOCK, words, **kw)) is None
    back = client.read_holding_registers(PART_BLOCK, count=48, **kw)
    bad = error_code(client.write_register(PART_BLOCK + 16, 0x0941, **kw))  # a tab: refused
    before = read()
    as_block = error_code(client.write_coil(2, True, **kw)) is None
    after_billet = settle(read, lambda w: w[4:6] != before[4:6])
    die = error_code(client.write_coil(3, True, **kw)) is None
    after_die = settle(read, lambda w: (w[22] << 16 | w[23]) < (after_billet[22] << 16 | after_billet[23]))
    return {
        "wrote": wrote,
        "read_back": None if back.isError() else list(back.registers),
        "written": words,
        "bad_write": bad,
        "coil_2": as_block,
        "coil_3": die,
        "before": before,
        "after_billet": after_billet,
        "after_die": after_die,
    }


def settle(read, done):
    """The registers once `done` holds of them, or after 3 s: the service takes a coil's
    command on its next turn, and the image follows the status snapshot after it (one a
    second at the latest; later on a loaded machine)."""
    until = time.monotonic() + 3.0
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
        "read_past_end": error_code(client.read_holding_registers(29, count=2, **kw)),
        "read_past_block": error_code(client.read_holding_registers(147, count=2, **kw)),
        "read_input": error_code(client.read_input_registers(0, count=2, **kw)),
        "write_coil_4": error_code(client.write_coil(4, True, **kw)),
        "read_coils": error_code(client.read_coils(0, count=2, **kw)),
        "other_unit": error_code(client.read_holding_registers(0, count=2, **{unit_kw(client.read_holding_registers): 2})),
    }

    images, heartbeats = [], []
    ack, billet, part = None, None, None
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
        elif billet is not None and part is None:
            part = dict(part_step(client, kw, read), images_before=len(images))
        time.sleep(0.01)
    client.close()
    json.dump(
        {"refused": refused, "images": images, "heartbeats": heartbeats, "ack": ack, "billet": billet, "part": part},
        sys.stdout,
    )


if __name__ == "__main__":
    main()
