"""An independent ROS 2 parameter client on Cyclone DDS (Python `cyclonedds`, no ROS):
what `ros2 param list/get/set/describe` do, over the rcl_interfaces services of a node,
with the rmw_cyclonedds service mapping; and a reader of `/parameter_events`.

    python param_peer.py DOMAIN NODE_NAME

Reads one JSON command per line on stdin and answers one JSON line on stdout:
  {"cmd": "list"}                          -> {"names": [...]}
  {"cmd": "get", "names": [...]}           -> {"values": [value, ...]}
  {"cmd": "set", "name": n, "value": v}    -> {"successful": b, "reason": s}
  {"cmd": "describe", "names": [...]}      -> {"descriptors": [{...}, ...]}
  {"cmd": "events"}                        -> {"events": [{"node", "changed": [[n, v]...], ...}]}
Values are JSON: bool, int, float, str, or list; {"type": "not_set"} for NOT_SET. A float
is sent as a DOUBLE, an int as an INTEGER (as `ros2 param set` parses its argument).
Prints {"ready": true} once every service has matched, {"error": ...} on failure.
"""
import json
import os
import random
import sys
import time
import types
from dataclasses import dataclass

DOMAIN, NODE = int(sys.argv[1]), sys.argv[2]

os.environ["CYCLONEDDS_URI"] = (
    "<CycloneDDS><Domain id='any'><General><Interfaces><NetworkInterface name='lo' multicast='false'/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><Peers><Peer address='127.0.0.1'/></Peers><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>60</MaxAutoParticipantIndex></Discovery></Domain></CycloneDDS>"
)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl import types as t  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


# rcl_interfaces (ROS 2 Humble/Jazzy), field order as in the .msg files.
@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class ParameterValue_(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterValue_"):
    type: t.uint8
    bool_value: bool
    integer_value: t.int64
    double_value: t.float64
    string_value: str
    byte_array_value: t.sequence[t.uint8]
    bool_array_value: t.sequence[bool]
    integer_array_value: t.sequence[t.int64]
    double_array_value: t.sequence[t.float64]
    string_array_value: t.sequence[str]


@dataclass
class Parameter_(IdlStruct, typename="rcl_interfaces::msg::dds_::Parameter_"):
    name: str
    value: ParameterValue_


@dataclass
class SetParametersResult_(IdlStruct, typename="rcl_interfaces::msg::dds_::SetParametersResult_"):
    successful: bool
    reason: str


@dataclass
class FloatingPointRange_(IdlStruct, typename="rcl_interfaces::msg::dds_::FloatingPointRange_"):
    from_value: t.float64
    to_value: t.float64
    step: t.float64


@dataclass
class IntegerRange_(IdlStruct, typename="rcl_interfaces::msg::dds_::IntegerRange_"):
    from_value: t.int64
    to_value: t.int64
    step: t.uint64


@dataclass
class ParameterDescriptor_(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterDescriptor_"):
    name: str
    type: t.uint8
    description: str
    additional_constraints: str
    read_only: bool
    dynamic_typing: bool
    floating_point_range: t.sequence[FloatingPointRange_, 1]
    integer_range: t.sequence[IntegerRange_, 1]


@dataclass
class ListParametersResult_(IdlStruct, typename="rcl_interfaces::msg::dds_::ListParametersResult_"):
    names: t.sequence[str]
    prefixes: t.sequence[str]


@dataclass
class ParameterEvent_(IdlStruct, typename="rcl_interfaces::msg::dds_::ParameterEvent_"):
    stamp: Time_
    node: str
    new_parameters: t.sequence[Parameter_]
    changed_parameters: t.sequence[Parameter_]
    deleted_parameters: t.sequence[Parameter_]


# rmw_cyclonedds services: a 16-byte header (client GUID half, sequence number) first.
def srv(name, req_fields, resp_fields):
    def make(kind, fields):
        annotations = {"client_guid": t.uint64, "seq": t.int64, **fields}
        cls = types.new_class(f"{name}_{kind}_", (IdlStruct,),
                              {"typename": f"rcl_interfaces::srv::dds_::{name}_{kind}_"},
                              lambda ns: ns.update({"__annotations__": annotations}))
        return dataclass(cls)
    return make("Request", req_fields), make("Response", resp_fields)


GetReq, GetResp = srv("GetParameters", {"names": t.sequence[str]}, {"values": t.sequence[ParameterValue_]})
SetReq, SetResp = srv("SetParameters", {"parameters": t.sequence[Parameter_]},
                      {"results": t.sequence[SetParametersResult_]})
ListReq, ListResp = srv("ListParameters", {"prefixes": t.sequence[str], "depth": t.uint64},
                        {"result": ListParametersResult_})
DescReq, DescResp = srv("DescribeParameters", {"names": t.sequence[str]},
                        {"descriptors": t.sequence[ParameterDescriptor_]})

NOT_SET, BOOL, INTEGER, DOUBLE, STRING = 0, 1, 2, 3, 4
BOOL_ARRAY, INTEGER_ARRAY, DOUBLE_ARRAY, STRING_ARRAY = 6, 7, 8, 9


def emit(obj):
    print(json.dumps(obj), flush=True)


def to_value(v):
    p = ParameterValue_(NOT_SET, False, 0, 0.0, "", [], [], [], [], [])
    if isinstance(v, bool):
        p.type, p.bool_value = BOOL, v
    elif isinstance(v, int):
        p.type, p.integer_value = INTEGER, v
    elif isinstance(v, float):
        p.type, p.double_value = DOUBLE, v
    elif isinstance(v, str):
        p.type, p.string_value = STRING, v
    elif isinstance(v, list) and all(isinstance(x, str) for x in v):
        p.type, p.string_array_value = STRING_ARRAY, v
    elif isinstance(v, list) and all(isinstance(x, float) for x in v):
        p.type, p.double_array_value = DOUBLE_ARRAY, v
    return p


def from_value(p):
    return {
        NOT_SET: lambda: {"type": "not_set"},
        BOOL: lambda: p.bool_value,
        INTEGER: lambda: p.integer_value,
        DOUBLE: lambda: p.double_value,
        STRING: lambda: p.string_value,
        BOOL_ARRAY: lambda: list(p.bool_array_value),
        INTEGER_ARRAY: lambda: list(p.integer_array_value),
        DOUBLE_ARRAY: lambda: list(p.double_array_value),
        STRING_ARRAY: lambda: list(p.string_array_value),
    }.get(p.type, lambda: {"type": p.type})()


dp = DomainParticipant(DOMAIN)
reliable = Qos(Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1)), Policy.History.KeepLast(100))
services = {}
for short, req_t, resp_t in [("get_parameters", GetReq, GetResp), ("set_parameters", SetReq, SetResp),
                             ("list_parameters", ListReq, ListResp), ("describe_parameters", DescReq, DescResp)]:
    w = DataWriter(dp, Topic(dp, f"rq/{NODE.strip('/')}/{short}Request", req_t), qos=reliable)
    r = DataReader(dp, Topic(dp, f"rr/{NODE.strip('/')}/{short}Reply", resp_t), qos=reliable)
    services[short] = (w, r, req_t)
events_r = DataReader(dp, Topic(dp, "rt/parameter_events", ParameterEvent_), qos=reliable)

deadline = time.time() + 20
while time.time() < deadline:
    if all(w.get_publication_matched_status().current_count > 0
           and r.get_subscription_matched_status().current_count > 0 for w, r, _ in services.values()) \
            and events_r.get_subscription_matched_status().current_count > 0:
        break
    time.sleep(0.05)
else:
    unmatched = [f"{short} {kind}" for short, (w, r, _) in services.items()
                 for kind, n in (("request writer", w.get_publication_matched_status().current_count),
                                 ("reply reader", r.get_subscription_matched_status().current_count)) if n == 0]
    if events_r.get_subscription_matched_status().current_count == 0:
        unmatched.append("/parameter_events reader")
    emit({"error": f"not matched with the node within 20 s: {', '.join(unmatched)}"})
    sys.exit(3)
time.sleep(0.3)

guid = random.getrandbits(63)
seq = 0


def call(short, **fields):
    """Sends a request (again every second, as DDS may drop the first ones while matching
    settles) and returns the reply to it, or None after 10 s."""
    global seq
    w, r, req_t = services[short]
    seq += 1
    end = time.time() + 10
    while time.time() < end:
        w.write(req_t(client_guid=guid, seq=seq, **fields))
        resend = time.time() + 1
        while time.time() < min(resend, end):
            for rep in r.take(N=10):
                if getattr(rep, "client_guid", None) == guid and rep.seq == seq:
                    return rep
            time.sleep(0.01)
    return None


events = []


def drain_events():
    for e in events_r.take(N=100):
        if isinstance(e, ParameterEvent_):
            events.append({"node": e.node,
                           "new": [[p.name, from_value(p.value)] for p in e.new_parameters],
                           "changed": [[p.name, from_value(p.value)] for p in e.changed_parameters],
                           "deleted": [p.name for p in e.deleted_parameters]})


emit({"ready": True})
for line in sys.stdin:
    if not line.strip():
        continue
    c = json.loads(line)
    cmd = c["cmd"]
    if cmd == "list":
        rep = call("list_parameters", prefixes=[], depth=0)
        emit({"error": "no reply"} if rep is None else {"names": list(rep.result.names),
                                                         "prefixes": list(rep.result.prefixes)})
    elif cmd == "get":
        rep = call("get_parameters", names=c["names"])
        emit({"error": "no reply"} if rep is None else {"values": [from_value(v) for v in rep.values]})
    elif cmd == "set":
        rep = call("set_parameters", parameters=[Parameter_(name=c["name"], value=to_value(c["value"]))])
        emit({"error": "no reply"} if rep is None or len(rep.results) != 1 else
             {"successful": rep.results[0].successful, "reason": rep.results[0].reason})
    elif cmd == "describe":
        rep = call("describe_parameters", names=c["names"])
        emit({"error": "no reply"} if rep is None else {"descriptors": [
            {"name": d.name, "type": d.type, "description": d.description,
             "additional_constraints": d.additional_constraints, "read_only": d.read_only,
             "floating_point_range": [[x.from_value, x.to_value, x.step] for x in d.floating_point_range],
             "integer_range": [[x.from_value, x.to_value, x.step] for x in d.integer_range]}
            for d in rep.descriptors]})
    elif cmd == "events":
        time.sleep(0.3)
        drain_events()
        emit({"events": events})
    else:
        emit({"error": f"unknown command {cmd}"})
