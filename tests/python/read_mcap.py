#!/usr/bin/env python3
"""Decode every message of a forgemon MCAP recording with the public Python packages.

This is the interop check of issue #3: `mcap` reads the file and `mcap-protobuf-support`
decodes each channel from the FileDescriptorSet stored in the file's schema records, with
nothing from forgemon. It prints one JSON object: per-topic message counts and schemas, and
the decoded fields of the messages, for tests/record_python.rs to compare with what it
wrote.

Usage: python3 tests/python/read_mcap.py FILE.mcap
Exit codes: 0 ok, 2 usage, 3 Python packages missing, 1 anything else.
"""

import json
import sys

try:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
except ImportError as err:  # pragma: no cover - depends on the machine
    print(
        f"read_mcap.py: {err}; install the packages with: "
        "python3 -m pip install mcap mcap-protobuf-support",
        file=sys.stderr,
    )
    sys.exit(3)


def optional(msg, field):
    """A proto3 `optional` field: its value, or None when it is absent."""
    return getattr(msg, field) if msg.HasField(field) else None


def alert_dict(alert):
    return {
        "kind": alert.kind,
        "blow": alert.blow,
        "reason": alert.reason,
        "figures": dict(sorted(alert.figures.items())),
    }


def describe(schema_name, msg):
    """The fields the Rust test checks, by message type."""
    if schema_name == "forgemon.SampleBatch":
        roles = [msg.DESCRIPTOR.fields_by_name["roles"].enum_type.values_by_number[r].name for r in msg.roles]
        return {
            "source": msg.source,
            "seq": msg.seq,
            "device_time_ns": msg.device_time_ns,
            "host_time_ns": msg.host_time_ns,
            "period_ns": msg.period_ns,
            "roles": roles,
            "n_values": len(msg.values),
            "values_head": list(msg.values[:6]),
            "values_sum": sum(msg.values),
        }
    if schema_name == "forgemon.BlowResult":
        return {
            "blow": msg.blow,
            "t_contact_s": msg.t_contact_s,
            "v_impact_mps": msg.v_impact_mps,
            "kinetic_in_J": optional(msg, "kinetic_in_J"),
            "plastic_J": optional(msg, "plastic_J"),
            "friction_J": optional(msg, "friction_J"),
            "damped_J": optional(msg, "damped_J"),
            "elastic_J": optional(msg, "elastic_J"),
            "efficiency": optional(msg, "efficiency"),
            "final_load_N": msg.final_load_N,
            "h_end_m": optional(msg, "h_end_m"),
            "class": getattr(msg, "class"),
            "alert": alert_dict(msg.alert) if msg.HasField("alert") else None,
            "residual": optional(msg, "residual"),
            "gap_s": msg.gap_s,
            "h_start_m": optional(msg, "h_start_m"),
            "method": optional(msg, "method"),
            "channels": list(msg.channels),
            "efficiency_sd": optional(msg, "efficiency_sd"),
            "acc_check": optional(msg, "acc_check"),
            "excluded": dict(msg.excluded),
        }
    if schema_name == "forgemon.Alert":
        return alert_dict(msg)
    if schema_name == "forgemon.BilletSummary":
        out = {field.name: getattr(msg, field.name) for field in msg.DESCRIPTOR.fields}
        for name in ("h_start_m", "h_start_off_sheet_m", "h_end_m", "friction_J", "efficiency", "first_hard_blow",
                     "part_id", "lot", "die_set"):
            out[name] = optional(msg, name)
        return out
    # The small messages (blow boundary, gap, status, config file): every scalar field,
    # with the .proto names.
    return {field.name: getattr(msg, field.name) for field in msg.DESCRIPTOR.fields}


def main(argv):
    if len(argv) != 2:
        print("usage: read_mcap.py FILE.mcap", file=sys.stderr)
        return 2
    topics = {}
    with open(argv[1], "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            entry = topics.setdefault(
                channel.topic,
                {
                    "count": 0,
                    "schema": schema.name,
                    "schema_encoding": schema.encoding,
                    "message_encoding": channel.message_encoding,
                    "messages": [],
                },
            )
            entry["count"] += 1
            item = describe(schema.name, decoded)
            item["log_time"] = message.log_time
            entry["messages"].append(item)
    out = {
        "topics": topics,
        "summary_message_count": summary.statistics.message_count if summary and summary.statistics else None,
    }
    json.dump(out, sys.stdout)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
