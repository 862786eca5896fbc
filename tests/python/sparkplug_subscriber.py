#!/usr/bin/env python3
"""An independent Sparkplug B subscriber for tests/sparkplug_mqtt.rs and the flap bench.

Compiles proto/sparkplug_b.proto with protoc (grpcio-tools) into a temporary directory,
connects to the broker with paho-mqtt in a persistent session (clean_session false, QoS 1,
as a historian would, so that what the broker queued while it was reconnecting reaches it),
subscribes to spBv1.0/#, and prints one JSON line per message received:

  {"topic": ..., "type": "NBIRTH", "seq": 0, "timestamp": ms, "dup": false, "rx_ms": ms,
   "metrics": {"bdSeq": {"value": 3, "datatype": 8, "timestamp": ms, "historical": false,
                         "null": false, "bits": null}, ...}}

("bits": a double's IEEE 754 bits as an integer, to compare exactly.)

After the DDATA count reaches REBIRTH_AFTER (if > 0) it sends one NCMD
`Node Control/Rebirth` to every node it has seen born. It stops when its standard input
closes (or after TIMEOUT seconds) and prints {"done": true}.

usage: sparkplug_subscriber.py HOST PORT CLIENT_ID TIMEOUT_S REBIRTH_AFTER
"""

import json
import os
import struct
import subprocess
import sys
import tempfile
import threading
import time

import paho.mqtt.client as mqtt

HERE = os.path.dirname(os.path.abspath(__file__))
PROTO_DIR = os.path.join(HERE, "..", "..", "proto")


def load_schema():
    """The Payload class generated from the published .proto."""
    out = tempfile.mkdtemp(prefix="spb_pb2_")
    subprocess.run(
        [sys.executable, "-m", "grpc_tools.protoc", f"-I{PROTO_DIR}", f"--python_out={out}",
         os.path.join(PROTO_DIR, "sparkplug_b.proto")],
        check=True,
    )
    sys.path.insert(0, out)
    import sparkplug_b_pb2  # noqa: E402 (generated just now)
    return sparkplug_b_pb2.Payload


def metric_value(m):
    if m.is_null:
        return None
    which = m.WhichOneof("value")
    return None if which is None else getattr(m, which)


def double_bits(v):
    if isinstance(v, float):
        return struct.unpack("<Q", struct.pack("<d", v))[0]
    return None


def main():
    host, port, client_id = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    timeout_s, rebirth_after = float(sys.argv[4]), int(sys.argv[5])
    Payload = load_schema()
    lock = threading.Lock()
    state = {"ddata": 0, "rebirth_sent": False, "nodes": set()}

    def emit(obj):
        with lock:
            sys.stdout.write(json.dumps(obj) + "\n")
            sys.stdout.flush()

    def on_connect(client, userdata, flags, reason_code, properties):
        client.subscribe("spBv1.0/#", qos=1)
        emit({"event": "connected", "session_present": bool(flags.session_present)})

    def on_message(client, userdata, msg):
        parts = msg.topic.split("/")
        kind = parts[2] if len(parts) > 2 else "?"
        if kind == "STATE" or kind == "NCMD" or kind == "DCMD":
            return
        p = Payload()
        p.ParseFromString(msg.payload)
        metrics = {
            m.name: {
                "value": metric_value(m),
                "datatype": m.datatype,
                "timestamp": m.timestamp if m.HasField("timestamp") else None,
                "historical": m.is_historical,
                "null": m.is_null,
                # A double's bits, exactly (a JSON reader may round the text by an ulp).
                "bits": double_bits(metric_value(m)),
            }
            for m in p.metrics
        }
        emit({
            "topic": msg.topic,
            "type": kind,
            "seq": p.seq if p.HasField("seq") else None,
            "timestamp": p.timestamp if p.HasField("timestamp") else None,
            "dup": bool(msg.dup),
            "rx_ms": int(time.time() * 1000),
            "metrics": metrics,
        })
        if kind == "NBIRTH":
            state["nodes"].add((parts[1], parts[3]))
        if kind == "DDATA":
            state["ddata"] += 1
            if rebirth_after > 0 and state["ddata"] >= rebirth_after and not state["rebirth_sent"]:
                state["rebirth_sent"] = True
                cmd = Payload()
                cmd.timestamp = int(time.time() * 1000)
                m = cmd.metrics.add()
                m.name = "Node Control/Rebirth"
                m.datatype = 11
                m.boolean_value = True
                for group, node in sorted(state["nodes"]):
                    client.publish(f"spBv1.0/{group}/NCMD/{node}", cmd.SerializeToString(), qos=0)
                emit({"event": "rebirth_sent"})

    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=False)
    client.on_connect = on_connect
    client.on_message = on_message
    client.reconnect_delay_set(min_delay=1, max_delay=1)
    client.connect(host, port, keepalive=5)
    client.loop_start()

    # Until the test closes our standard input, or the timeout.
    def wait_stdin():
        sys.stdin.read()
    reader = threading.Thread(target=wait_stdin, daemon=True)
    reader.start()
    reader.join(timeout_s)
    client.disconnect()
    client.loop_stop()
    emit({"done": True})


if __name__ == "__main__":
    main()
