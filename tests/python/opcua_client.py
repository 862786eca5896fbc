#!/usr/bin/env python3
"""An independent OPC UA client (asyncua) for forgemon's OPC UA Metal Forming server.

The client of issue 21 §2, for tests/opcua_python.rs. It decodes nothing with forgemon.

  demo URL SECONDS
      Anonymous session. Browses Objects/Machines/Hammer (Identification, the
      FormingWorkingUnit and its values and conditions), subscribes to the
      BlowCompletedEventType events and the AlarmConditionType events of the machine,
      reads the counters and values in one Read request every 50 ms, and acknowledges the
      first raised condition with its condition's Acknowledge method (after trying an
      EventId that is not the condition's). Reads each value's EngineeringUnits and type
      definition. After blow 3 calls the working unit's SetPart("P-000418", "", "18")
      (after trying a part id with a leading space), and four blows later ChangeDies("19").
      Stops after SECONDS or when the server goes.
  companion URL SECONDS
      Anonymous, against a server given the companion NodeSet2 files. Reads the type
      definitions of the machine (in Machinery's Machines folder), its working unit and its
      Identification, and the Identification's properties; checks that every mandatory
      child the types declare (outside namespace 0, with their supertypes and interfaces) is
      on the instance, four levels down; reads the blow event type's supertype; subscribes
      to the machine's events with select clauses that name Metal Forming's CyclicEventType
      (CycleCount, PartId) and collects them until SECONDS or the server goes; after the
      first event calls SetPart("P-7", "", "").
  auth URL SERVER_CERT_DER USER PASSWORD WORKDIR
      Tries an anonymous session, a wrong password and the right password (over
      Basic256Sha256 SignAndEncrypt with a self-signed client certificate made in WORKDIR);
      reads the CycleCounter with the right one.
  throttle URL SERVER_CERT_DER USER PASSWORD WORKDIR N
      N wrong passwords in a row, one session each (as `auth` makes them), then the right
      one; prints when each try started and ended (monotonic seconds) and how it ended.
  peers URL SERVER_CERT_DER USER PASSWORD WORKDIR
      Two peers: A from 127.0.0.1, B from 127.0.0.2. B logs in alone first; then A sends
      10 wrong passwords in a row and 8 more at once, and while A's 8 wait, B logs in
      again with the right password. Prints each try's start, end and outcome.
  cap URL
      Anonymous. Opens two raw connections that send nothing, then sessions A and B, then a
      third raw connection; closes A and opens a fourth. Prints which raw connections the
      server closed within a second of the step that followed them, and what A and B read.

Prints one JSON object. Exit codes: 0 ok, 2 usage, 3 asyncua missing, 1 anything else.
"""

import asyncio
import json
import sys
import time
from pathlib import Path

try:
    from asyncua import Client, ua
    from asyncua.common.events import get_filter_from_event_type
    from asyncua.crypto import security_policies
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID
except ImportError as err:  # pragma: no cover - depends on the machine
    print(f"opcua_client.py: {err}; install it with: python3 -m pip install asyncua", file=sys.stderr)
    sys.exit(3)

MODEL_NS = "urn:forgemon:UA:MetalForming"
FORGEMON_NS = "urn:forgemon:UA"
APP_URI = "urn:forgemon:test:opcua_client"
VALUES = ["CycleCounter", "BilletCounter", "PeakLoad", "BilletHeight", "ImpactEnergy", "PlasticEnergy", "Efficiency"]


def plain(v):
    """A JSON-able form of a value asyncua decoded."""
    if isinstance(v, (bool, int, float, str)) or v is None:
        return v
    if isinstance(v, bytes):
        return v.hex()
    if isinstance(v, ua.LocalizedText):
        return v.Text
    return str(v)


class Handler:
    """Events and data changes into an asyncio queue, for the main loop."""

    def __init__(self, queue):
        self.queue = queue

    def event_notification(self, event):
        fields = event.get_event_props_as_fields_dict()
        self.queue.put_nowait(("event", {k: v.Value for k, v in fields.items()}))

    def datachange_notification(self, node, val, data):
        self.queue.put_nowait(("data", val))


async def event_filter(event_type):
    """asyncua's filter for `event_type`, with two changes for async-opcua 0.19: the
    where clause is `OfType(event_type)` (the standard form; async-opcua does not match the
    `InList(EventType, ...)` asyncua generates), and asyncua's ConditionId clause (no
    browse path) is left out (async-opcua drops it, which would shift every field)."""
    f = await get_filter_from_event_type([event_type])
    f.SelectClauses = [c for c in f.SelectClauses if c.BrowsePath]
    where = ua.ContentFilterElement(FilterOperator=ua.FilterOperator.OfType)
    where.FilterOperands.append(ua.LiteralOperand(Value=ua.Variant(event_type.nodeid)))
    f.WhereClause = ua.ContentFilter(Elements=[where])
    return f


async def quiet_disconnect(client):
    """Disconnect; a server that has gone already is no error."""
    try:
        await client.disconnect()
    except Exception:
        pass


async def connect(client, deadline):
    """Connect, retrying while the server is not up yet."""
    while True:
        try:
            await client.connect()
            return
        except (OSError, asyncio.TimeoutError, ua.UaError):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)


async def browse_names(node, depth):
    """`{ "ns:Name": children }` below `node`, `depth` levels down."""
    out = {}
    for child in await node.get_children():
        bn = await child.read_browse_name()
        key = f"{bn.NamespaceIndex}:{bn.Name}"
        out[key] = await browse_names(child, depth - 1) if depth > 1 else {}
    return out


async def demo(url, seconds):
    deadline = time.monotonic() + seconds
    client = Client(url, timeout=4)
    await connect(client, deadline)
    result = {"events": [], "alarms": [], "reads": [], "changes": [], "ack": None}
    try:
        mf = await client.get_namespace_index(MODEL_NS)
        fm = await client.get_namespace_index(FORGEMON_NS)
        result["namespaces"] = {"model": mf, "forgemon": fm}
        machine = await client.nodes.objects.get_child([f"{mf}:Machines", f"{mf}:Hammer"])
        unit = await machine.get_child(f"{mf}:FormingWorkingUnit")
        result["browse"] = await browse_names(machine, 3)
        ident = await machine.get_child(f"{mf}:Identification")
        result["identification"] = {
            (await c.read_browse_name()).Name: plain(await c.read_value()) for c in await ident.get_children()
        }
        value_nodes = [await unit.get_child(f"{mf if n in ('CycleCounter', 'PeakLoad', 'BilletHeight') else fm}:{n}") for n in VALUES]
        queue = asyncio.Queue()
        sub = await client.create_subscription(20, Handler(queue))
        blow_type = client.get_node(ua.NodeId("BlowCompletedEventType", fm))
        await sub.subscribe_events(machine, evfilter=await event_filter(blow_type), queuesize=100)
        alarm_type = client.get_node(ua.ObjectIds.AlarmConditionType)
        await sub.subscribe_events(machine, evfilter=await event_filter(alarm_type), queuesize=100)
        await sub.subscribe_data_change(value_nodes[0], queuesize=100)
        result["subscribed_at"] = plain(await value_nodes[0].read_value())
        result["units"] = await engineering_units(unit, mf, fm)
        result["calls"] = {}
        cond_node, pending_ack = None, None
        while time.monotonic() < deadline:
            try:
                result["reads"].append([plain(v) for v in await client.read_values(value_nodes)])
            except Exception:  # the demo has stopped: its server is gone
                break
            while not queue.empty():
                kind, item = queue.get_nowait()
                if kind == "data":
                    result["changes"].append(plain(item))
                    continue
                fields = {k: plain(v) for k, v in item.items()}
                etype = item.get("EventType")
                if etype == ua.NodeId(ua.ObjectIds.AlarmConditionType):
                    result["alarms"].append(fields)
                    if result["ack"] is None and pending_ack is None and item.get("ActiveState/Id"):
                        pending_ack = (fields["ConditionName"], item["EventId"])
                else:
                    result["events"].append(fields)
            await part_calls(unit, fm, result)
            if pending_ack is not None and result["ack"] is None:
                name, event_id = pending_ack
                cond_node = await unit.get_child(f"{fm}:{name}")
                ack = {"condition": name, "event_id": event_id.hex()}
                try:
                    await cond_node.call_method("0:Acknowledge", ua.Variant(b"not-an-event-id", ua.VariantType.ByteString), ua.LocalizedText("wrong"))
                    ack["wrong_event_id"] = "Good"
                except ua.UaStatusCodeError as e:
                    ack["wrong_event_id"] = ua.StatusCode(e.code).name
                ack["acked_before"] = await (await cond_node.get_child(["0:AckedState", "0:Id"])).read_value()
                await cond_node.call_method("0:Acknowledge", ua.Variant(event_id, ua.VariantType.ByteString), ua.LocalizedText("seen"))
                ack["called"] = True
                result["ack"] = ack
            elif result["ack"] is not None and "acked_after" not in result["ack"]:
                acked = await (await cond_node.get_child(["0:AckedState", "0:Id"])).read_value()
                if acked:
                    result["ack"]["acked_after"] = acked
                    try:
                        await cond_node.call_method("0:Acknowledge", ua.Variant(pending_ack[1], ua.VariantType.ByteString), ua.LocalizedText("again"))
                        result["ack"]["again"] = "Good"
                    except ua.UaStatusCodeError as e:
                        result["ack"]["again"] = ua.StatusCode(e.code).name
            await asyncio.sleep(0.05)
    finally:
        await quiet_disconnect(client)
    return result


async def engineering_units(unit, mf, fm):
    """Each value's EngineeringUnits (EUInformation) and type definition."""
    out = {}
    for name in VALUES + ["ImpactVelocity"]:
        node = await unit.get_child(f"{mf if name in ('CycleCounter', 'PeakLoad', 'BilletHeight') else fm}:{name}")
        eu = await (await node.get_child("0:EngineeringUnits")).read_value()
        out[name] = {
            "namespace": eu.NamespaceUri,
            "unit_id": eu.UnitId,
            "display": eu.DisplayName.Text,
            "description": eu.Description.Text,
            "type": (await node.read_type_definition()).Identifier,
        }
    return out


async def part_calls(unit, fm, result):
    """SetPart after blow 3 (a bad id first), ChangeDies four blows later; each with the
    cycle counter just before the call."""
    calls = result["calls"]
    counter = result["reads"][-1][0] if result["reads"] else 0
    if "set_part" not in calls and counter >= 3:
        try:
            await unit.call_method(f"{fm}:SetPart", " P-1", "", "")
            calls["bad_part"] = "Good"
        except ua.UaStatusCodeError as e:
            calls["bad_part"] = ua.StatusCode(e.code).name
        await unit.call_method(f"{fm}:SetPart", "P-000418", "", "18")
        calls["set_part"] = counter
    elif "set_part" in calls and "change_dies" not in calls and counter >= calls["set_part"] + 4:
        await unit.call_method(f"{fm}:ChangeDies", "19")
        calls["change_dies"] = counter


MACHINERY = "http://opcfoundation.org/UA/Machinery/"
MACHINE_TOOL = "http://opcfoundation.org/UA/MachineTool/"
METAL_FORMING = "http://opcfoundation.org/UA/MetalForming/"
MANDATORY = ua.NodeId(ua.ObjectIds.ModellingRule_Mandatory)


async def qualified(client, node):
    """`URI|Name` of a node's browse name."""
    bn = await node.read_browse_name()
    return f"{(await client.get_namespace_array())[bn.NamespaceIndex]}|{bn.Name}"


async def targets(node, ref, inverse=False):
    direction = ua.BrowseDirection.Inverse if inverse else ua.BrowseDirection.Forward
    refs = await node.get_references(refs=ref, direction=direction, includesubtypes=False)
    return [node.session.get_node(r.NodeId) if hasattr(node, "session") else r.NodeId for r in refs]


async def declarations(client, ty):
    """The declarations under a type, its supertypes and interfaces outside namespace 0:
    `{browse name: (declaration node, mandatory)}`, the most derived first."""
    out, todo, seen = {}, [ty], set()
    while todo:
        t = todo.pop(0)
        if t.nodeid.NamespaceIndex == 0 or t.nodeid in seen:
            continue
        seen.add(t.nodeid)
        for ref in (ua.ObjectIds.HasComponent, ua.ObjectIds.HasProperty, ua.ObjectIds.HasAddIn, ua.ObjectIds.HasOrderedComponent):
            for r in await t.get_references(refs=ref, direction=ua.BrowseDirection.Forward, includesubtypes=False):
                d = client.get_node(r.NodeId)
                key = r.BrowseName.to_string()
                if key in out:
                    continue
                rules = await d.get_references(refs=ua.ObjectIds.HasModellingRule, direction=ua.BrowseDirection.Forward)
                out[key] = (d, any(x.NodeId == MANDATORY for x in rules))
        for r in await t.get_references(refs=ua.ObjectIds.HasInterface, direction=ua.BrowseDirection.Forward, includesubtypes=False):
            todo.append(client.get_node(r.NodeId))
        for r in await t.get_references(refs=ua.ObjectIds.HasSubtype, direction=ua.BrowseDirection.Inverse, includesubtypes=False):
            todo.append(client.get_node(r.NodeId))
    return out


async def mandatory_check(client, instance, path, depth, report):
    """Every mandatory declaration of the instance's type (and of the declaration the
    instance was made from) has a child of the same browse name; counts what it checked."""
    if depth == 0:
        return
    ty = client.get_node(await instance.read_type_definition())
    decls = await declarations(client, ty)
    children = {}
    for c in await instance.get_children(refs=ua.ObjectIds.Aggregates):
        children[(await c.read_browse_name()).to_string()] = c
    for key, (decl, mandatory) in decls.items():
        if not mandatory:
            continue
        report["checked"] += 1
        if key not in children:
            report["missing"].append(f"{path}/{key}")
            continue
        await mandatory_check(client, children[key], f"{path}/{key}", depth - 1, report)


async def companion(url, seconds):
    deadline = time.monotonic() + seconds
    client = Client(url, timeout=4)
    await connect(client, deadline)
    result = {"events": []}
    try:
        nss = await client.get_namespace_array()
        mf, mach, mt, forming = (nss.index(u) for u in (MODEL_NS, MACHINERY, MACHINE_TOOL, METAL_FORMING))
        machine = await client.nodes.objects.get_child([f"{mach}:Machines", f"{mf}:Hammer"])
        unit = await machine.get_child(f"{mf}:FormingWorkingUnit")
        ident = await machine.get_child(f"{nss.index('http://opcfoundation.org/UA/DI/')}:Identification")
        result["types"] = {
            name: await qualified(client, client.get_node(await node.read_type_definition()))
            for name, node in (("machine", machine), ("unit", unit), ("identification", ident))
        }
        result["identification"] = {
            await qualified(client, c): plain(await c.read_value()) for c in await ident.get_children()
        }
        report = {"checked": 0, "missing": []}
        await mandatory_check(client, machine, "Hammer", 4, report)
        result["mandatory"] = report
        blow_type = client.get_node(ua.NodeId("BlowCompletedEventType", nss.index(FORGEMON_NS)))
        supers = await blow_type.get_references(refs=ua.ObjectIds.HasSubtype, direction=ua.BrowseDirection.Inverse)
        result["event_supertype"] = await qualified(client, client.get_node(supers[0].NodeId))
        # The standard's way to read a cyclic event: the select clauses name CyclicEventType.
        cyclic = ua.NodeId(1016, forming)
        evfilter = ua.EventFilter()
        for ty, name in ((ua.NodeId(ua.ObjectIds.BaseEventType), "0:EventType"), (cyclic, f"{forming}:CycleCount"), (cyclic, f"{forming}:PartId")):
            op = ua.SimpleAttributeOperand(TypeDefinitionId=ty, BrowsePath=[ua.QualifiedName.from_string(name)], AttributeId=ua.AttributeIds.Value)
            evfilter.SelectClauses.append(op)
        where = ua.ContentFilterElement(FilterOperator=ua.FilterOperator.OfType)
        where.FilterOperands.append(ua.LiteralOperand(Value=ua.Variant(cyclic)))
        evfilter.WhereClause = ua.ContentFilter(Elements=[where])
        queue = asyncio.Queue()
        sub = await client.create_subscription(20, Handler(queue))
        await sub.subscribe_events(machine, evfilter=evfilter, queuesize=100)
        while time.monotonic() < deadline:
            try:
                await machine.read_browse_name()
            except Exception:  # the demo has stopped: its server is gone
                break
            while not queue.empty():
                kind, item = queue.get_nowait()
                if kind == "event":
                    result["events"].append({k: plain(v) for k, v in item.items()})
            if result["events"] and "set_part" not in result:
                # What the next blows are forged as: their events' PartId.
                result["set_part"] = result["events"][-1]["CycleCount"]
                await unit.call_method(f"{nss.index(FORGEMON_NS)}:SetPart", "P-7", "", "")
            await asyncio.sleep(0.05)
    finally:
        await quiet_disconnect(client)
    return result


async def try_session(client):
    """'ok' and the CycleCounter, or the error's text."""
    try:
        await client.connect()
    except Exception as e:  # the refusal is what is being tested
        return {"error": f"{type(e).__name__}: {e}"}
    try:
        mf = await client.get_namespace_index(MODEL_NS)
        node = await client.nodes.objects.get_child([f"{mf}:Machines", f"{mf}:Hammer", f"{mf}:FormingWorkingUnit", f"{mf}:CycleCounter"])
        return {"ok": plain(await node.read_value())}
    finally:
        await client.disconnect()


async def client_cert(workdir):
    """The test client's key and self-signed certificate in `workdir` (made once, kept)."""
    work = Path(workdir)
    key, cert = work / "client-key.pem", work / "client-cert.der"
    await setup_self_signed_certificate(
        key, cert, APP_URI, "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH], {"commonName": "forgemon test client"}
    )
    return key, cert


async def secure(url, server_cert, key, cert, name, pw):
    """A client for the Basic256Sha256 SignAndEncrypt endpoint, as `name` (None: anonymous)."""
    c = Client(url, timeout=4)
    c.application_uri = APP_URI
    if name is not None:
        c.set_user(name)
        c.set_password(pw)
    await c.set_security(
        security_policies.SecurityPolicyBasic256Sha256, str(cert), str(key),
        server_certificate=server_cert, mode=ua.MessageSecurityMode.SignAndEncrypt,
    )
    return c


async def wait_for_server(url, deadline):
    """Until a TCP connection to the server opens."""
    while True:
        try:
            _, w = await asyncio.open_connection(*url.removeprefix("opc.tcp://").rstrip("/").rsplit(":", 1))
            w.close()
            return
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)


async def auth(url, server_cert, user, password, workdir):
    key, cert = await client_cert(workdir)
    await wait_for_server(url, time.monotonic() + 20)
    return {
        "anonymous_none": await try_session(Client(url, timeout=4)),
        "anonymous_encrypted": await try_session(await secure(url, server_cert, key, cert, None, None)),
        "wrong_password": await try_session(await secure(url, server_cert, key, cert, user, password + "x")),
        "right_password": await try_session(await secure(url, server_cert, key, cert, user, password)),
    }


async def throttle(url, server_cert, user, password, workdir, n):
    key, cert = await client_cert(workdir)
    await wait_for_server(url, time.monotonic() + 20)
    tries = []
    for _ in range(n):
        started = time.monotonic()
        r = await try_session(await secure(url, server_cert, key, cert, user, password + "x"))
        tries.append({"start": started, "end": time.monotonic(), **r})
    started = time.monotonic()
    right = await try_session(await secure(url, server_cert, key, cert, user, password))
    return {"wrong": tries, "right": {"start": started, "end": time.monotonic(), **right}}


def from_source(client, source_ip):
    """`client`, connecting from `source_ip` (any 127.0.0.0/8 address is this machine's)."""
    from asyncua.client.ua_client import UaClientState

    ua_client = client.uaclient

    async def connect_socket(host, port):
        ua_client._set_state(UaClientState.CONNECTING)
        await asyncio.wait_for(
            asyncio.get_running_loop().create_connection(
                ua_client._make_protocol, host, port, local_addr=(source_ip, 0)
            ),
            ua_client._timeout,
        )
        ua_client._set_state(UaClientState.SOCKET_OPEN)

    ua_client.connect_socket = connect_socket
    return client


async def timed(coro):
    started = time.monotonic()
    r = await coro
    return {"start": started, "end": time.monotonic(), **r}


async def peers(url, server_cert, user, password, workdir):
    key, cert = await client_cert(workdir)
    await wait_for_server(url, time.monotonic() + 20)

    async def login(source, pw):
        return await timed(try_session(from_source(await secure(url, server_cert, key, cert, user, pw), source)))

    b_alone = await login("127.0.0.2", password)
    a_first = [await login("127.0.0.1", password + "x") for _ in range(10)]
    a_queue = [asyncio.create_task(login("127.0.0.1", password + "x")) for _ in range(8)]
    await asyncio.sleep(0.3)
    b_during = await login("127.0.0.2", password)
    return {"b_alone": b_alone, "a_first": a_first, "a_queue": list(await asyncio.gather(*a_queue)), "b_during": b_during}


async def closed_within(reader, seconds):
    """Whether the server closed this raw connection within `seconds`."""
    try:
        return await asyncio.wait_for(reader.read(1), seconds) == b""
    except asyncio.TimeoutError:
        return False
    except ConnectionError:
        return True


async def cap(url):
    host, port = url.removeprefix("opc.tcp://").rstrip("/").rsplit(":", 1)
    await wait_for_server(url, time.monotonic() + 20)
    raw = [await asyncio.open_connection(host, port) for _ in range(2)]
    a = Client(url, timeout=4)
    a_read = await timed(session_read(a))
    b = Client(url, timeout=4)
    b_read = await timed(session_read(b))
    out = {"a": a_read, "b": b_read}
    out["raw1_closed"] = await closed_within(raw[0][0], 1.0)
    out["raw2_closed"] = await closed_within(raw[1][0], 1.0)
    raw3 = await asyncio.open_connection(host, port)
    out["raw3_closed"] = await closed_within(raw3[0], 1.0)
    await a.disconnect()
    await asyncio.sleep(0.3)
    raw4 = await asyncio.open_connection(host, port)
    out["raw4_closed"] = await closed_within(raw4[0], 1.0)
    await b.disconnect()
    for _, w in [*raw, raw3, raw4]:
        w.close()
    return out


async def session_read(client):
    """Connect `client` and read the CycleCounter, leaving the session open."""
    try:
        await client.connect()
        mf = await client.get_namespace_index(MODEL_NS)
        node = await client.nodes.objects.get_child([f"{mf}:Machines", f"{mf}:Hammer", f"{mf}:FormingWorkingUnit", f"{mf}:CycleCounter"])
        return {"ok": plain(await node.read_value())}
    except Exception as e:  # the refusal is what is being tested
        return {"error": f"{type(e).__name__}: {e}"}


def main():
    args = sys.argv[1:]
    if len(args) == 3 and args[0] == "demo":
        out = asyncio.run(demo(args[1], float(args[2])))
    elif len(args) == 3 and args[0] == "companion":
        out = asyncio.run(companion(args[1], float(args[2])))
    elif len(args) == 6 and args[0] == "auth":
        out = asyncio.run(auth(*args[1:]))
    elif len(args) == 6 and args[0] == "peers":
        out = asyncio.run(peers(*args[1:]))
    elif len(args) == 2 and args[0] == "cap":
        out = asyncio.run(cap(args[1]))
    elif len(args) == 7 and args[0] == "throttle":
        out = asyncio.run(throttle(*args[1:6], int(args[6])))
    else:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
