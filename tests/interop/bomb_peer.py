"""An independent camera on Cyclone DDS (Python `cyclonedds`, no ROS) that sends the BEVT
node image bombs and truncated frames between good frames (issue 6 §2).

    python bomb_peer.py DOMAIN DIR

DIR holds plan.json {"width", "height", "warmup": FILE, "messages": [{"id", "kind":
"raw"|"compressed", "file", "format"}]} and the files it names (raw rgb8 frames of
width x height, or compressed bytes). The peer publishes the warm-up frame (frame_id
"warmup") at 10 Hz until DIR/go exists (the test has initialised the track on it), then
every message of the plan in order, 0.15 s apart, with its id as the header's frame_id,
and exits. The test reads the node's statuses (their header echoes the frame_id).
"""
import json
import os
import pathlib
import sys
import time
from dataclasses import dataclass

DOMAIN, DIR = int(sys.argv[1]), pathlib.Path(sys.argv[2])

# Loopback only, no multicast, unicast discovery to this host, a receive buffer large
# enough for the frames.
os.environ["CYCLONEDDS_URI"] = (
    "<CycloneDDS><Domain id='any'><General><Interfaces><NetworkInterface name='lo' multicast='false'/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><Peers><Peer address='127.0.0.1'/></Peers><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>60</MaxAutoParticipantIndex></Discovery>"
    "<Internal><SocketReceiveBufferSize min='4MiB'/></Internal></Domain></CycloneDDS>"
)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl import types as t  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_
    frame_id: str


@dataclass
class Image_(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header_
    height: t.uint32
    width: t.uint32
    encoding: str
    is_bigendian: t.uint8
    step: t.uint32
    data: t.sequence[t.uint8]


@dataclass
class CompressedImage_(IdlStruct, typename="sensor_msgs::msg::dds_::CompressedImage_"):
    header: Header_
    format: str
    data: t.sequence[t.uint8]


# Seconds between plan messages, and the longest wait for the test's go-ahead.
SPACING_S = 0.15
WARMUP_LIMIT_S = 30.0

plan = json.loads((DIR / "plan.json").read_text())
W, H = plan["width"], plan["height"]

dp = DomainParticipant(DOMAIN)
best_effort = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1))
raw_w = DataWriter(dp, Topic(dp, "rt/image_raw", Image_), qos=best_effort)
cmp_w = DataWriter(dp, Topic(dp, "rt/image_raw/compressed", CompressedImage_), qos=best_effort)


def header(frame_id):
    now = time.time_ns()
    return Header_(stamp=Time_(sec=now // 1_000_000_000, nanosec=now % 1_000_000_000), frame_id=frame_id)


def raw(frame_id, name):
    data = (DIR / name).read_bytes()
    raw_w.write(Image_(header=header(frame_id), height=H, width=W, encoding="rgb8",
                       is_bigendian=0, step=W * 3, data=list(data)))


deadline = time.time() + 20
while not all(w.get_publication_matched_status().current_count > 0 for w in (raw_w, cmp_w)):
    if time.time() > deadline:
        print(json.dumps({"error": "no match with the node within 20 s"}), flush=True)
        sys.exit(3)
    time.sleep(0.05)

deadline = time.time() + WARMUP_LIMIT_S
while not (DIR / "go").exists():
    if time.time() > deadline:
        print(json.dumps({"error": "no go-ahead from the test"}), flush=True)
        sys.exit(4)
    raw("warmup", plan["warmup"])
    time.sleep(0.1)

for m in plan["messages"]:
    if m["kind"] == "raw":
        raw(m["id"], m["file"])
    else:
        cmp_w.write(CompressedImage_(header=header(m["id"]), format=m["format"],
                                     data=list((DIR / m["file"]).read_bytes())))
    print(json.dumps({"sent": m["id"]}), flush=True)
    time.sleep(SPACING_S)
