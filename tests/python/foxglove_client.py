#!/usr/bin/env python3
"""A Foxglove WebSocket client independent of forgemon's code (tests/foxglove_python.rs).

Connects to URL with the `websockets` package, asking for the foxglove.websocket.v1
subprotocol; reads serverInfo and the advertised channels; subscribes to /results and to
every /samples/<source> channel; decodes the message data frames with the `protobuf`
package from the schema the server advertised (base64 FileDescriptorSet), and nothing of
forgemon's. Stops after RESULTS decoded results (and at least one sample batch), then prints
JSON (floats as their repr() text, to be parsed exactly): the server's info, the channels, and each decoded message with its subscription id and
log time.

Usage: foxglove_client.py URL RESULTS DEADLINE_S
Exit codes: 0 done, 2 timed out or protocol error, 3 packages missing.
"""

import asyncio
import base64
import json
import struct
import sys
import time

try:
    import websockets
    from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory
except ImportError as e:  # pragma: no cover - the test says how to install
    print(f"missing package: {e}", file=sys.stderr)
    sys.exit(3)

SUBPROTOCOL = "foxglove.websocket.v1"


def exact(obj):
    """Floats as their shortest round-trip text, so the reader parses the very same double."""
    if isinstance(obj, float):
        return repr(obj)
    if isinstance(obj, dict):
        return {k: exact(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [exact(v) for v in obj]
    return obj


def message_class(channel):
    """The protobuf class of a channel, from the schema it was advertised with."""
    assert channel["encoding"] == "protobuf", channel
    assert channel["schemaEncoding"] == "protobuf", channel
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


async def connect(url, deadline):
    """The demo starts its server a moment after it prints the address: retry until then."""
    while True:
        try:
            return await websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None)
        except (OSError, websockets.exceptions.InvalidHandshake):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)


async def run(url, want_results, deadline):
    ws = await connect(url, deadline)
    out = {"subprotocol": ws.subprotocol, "channels": {}, "results": [], "samples": [], "status": []}
    channels = {}
    subscriptions = {}
    next_sub = 100
    async with ws:
        while len(out["results"]) < want_results or not out["samples"]:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"got {len(out['results'])} results, {len(out['samples'])} sample batches")
            frame = await asyncio.wait_for(ws.recv(), timeout=left)
            if isinstance(frame, str):
                msg = json.loads(frame)
                op = msg["op"]
                if op == "serverInfo":
                    out["server_info"] = msg
                elif op == "advertise":
                    subscribe = []
                    for ch in msg["channels"]:
                        channels[ch["id"]] = ch
                        out["channels"][ch["topic"]] = {
                            k: ch[k] for k in ("id", "encoding", "schemaName", "schemaEncoding")
                        }
                        if ch["topic"] == "/results" or ch["topic"].startswith("/samples/"):
                            subscriptions[next_sub] = (ch["topic"], message_class(ch))
                            subscribe.append({"id": next_sub, "channelId": ch["id"]})
                            next_sub += 1
                    if subscribe:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subscribe}))
                elif op == "status":
                    out["status"].append(msg)
                continue
            # Binary: opcode 0x01, u32 subscription id, u64 log time ns, payload (spec).
            opcode, sub_id, log_time = struct.unpack_from("<BIQ", frame, 0)
            assert opcode == 0x01, opcode
            topic, cls = subscriptions[sub_id]
            decoded = cls.FromString(frame[13:])
            d = json_format.MessageToDict(decoded, preserving_proto_field_name=True)
            entry = {"subscription": sub_id, "topic": topic, "log_time_ns": log_time, "message": exact(d)}
            if topic == "/results":
                out["results"].append(entry)
            elif len(out["samples"]) < 2:
                # The values as doubles, not MessageToDict's strings for int64s.
                entry["message"].pop("values", None)
                entry["message"]["values_len"] = len(decoded.values)
                entry["message"]["values_first_last"] = exact(list(decoded.values[:1]) + list(decoded.values[-1:]))
                out["samples"].append(entry)
    return out


def main():
    url, want, deadline_s = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    try:
        out = asyncio.run(run(url, want, time.monotonic() + deadline_s))
    except (TimeoutError, asyncio.TimeoutError, OSError, websockets.exceptions.WebSocketException) as e:
        print(f"foxglove_client.py: {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(2)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
