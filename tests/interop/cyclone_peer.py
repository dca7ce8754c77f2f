"""An independent ROS 2 peer on Cyclone DDS (Python `cyclonedds`, no ROS): publishes
camera frames to the BEVT node, calls its `reinit` service (rmw_cyclonedds wire
mapping), and records the detections it publishes.

    python cyclone_peer.py DOMAIN FRAMES_DIR RATE_HZ

FRAMES_DIR holds meta.json {"width", "height", "count", "init": [x, y, w, h]} and raw
rgb8 frames frame_%05d.rgb. Prints one JSON object per line: {"reinit": {...}} and then
{"frame": i, "box": [x, y, w, h], "score": s} per detection received.
"""
import json
import os
import pathlib
import random
import sys
import time
from dataclasses import dataclass, field

DOMAIN, FRAMES, RATE = int(sys.argv[1]), pathlib.Path(sys.argv[2]), float(sys.argv[3])

# Loopback only, no multicast, unicast discovery to this host, a receive buffer large
# enough for 1280x720 frames.
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
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


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
class Point_(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Quaternion_(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclass
class Pose_(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point_
    orientation: Quaternion_


@dataclass
class PoseWithCovariance_(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose_
    covariance: t.array[t.float64, 36]


@dataclass
class Point2D_(IdlStruct, typename="vision_msgs::msg::dds_::Point2D_"):
    x: t.float64
    y: t.float64


@dataclass
class Pose2D_(IdlStruct, typename="vision_msgs::msg::dds_::Pose2D_"):
    position: Point2D_
    theta: t.float64


@dataclass
class BoundingBox2D_(IdlStruct, typename="vision_msgs::msg::dds_::BoundingBox2D_"):
    center: Pose2D_
    size_x: t.float64
    size_y: t.float64


@dataclass
class ObjectHypothesis_(IdlStruct, typename="vision_msgs::msg::dds_::ObjectHypothesis_"):
    class_id: str
    score: t.float64


@dataclass
class ObjectHypothesisWithPose_(IdlStruct, typename="vision_msgs::msg::dds_::ObjectHypothesisWithPose_"):
    hypothesis: ObjectHypothesis_
    pose: PoseWithCovariance_


@dataclass
class Detection2D_(IdlStruct, typename="vision_msgs::msg::dds_::Detection2D_"):
    header: Header_
    results: t.sequence[ObjectHypothesisWithPose_]
    bbox: BoundingBox2D_
    id: str


@dataclass
class Detection2DArray_(IdlStruct, typename="vision_msgs::msg::dds_::Detection2DArray_"):
    header: Header_
    detections: t.sequence[Detection2D_]


# rmw_cyclonedds services: a 16-byte header (lower half of the client GUID, sequence
# number) precedes the request and is echoed in the reply.
@dataclass
class Reinit_Request_(IdlStruct, typename="bevt_msgs::srv::dds_::Reinit_Request_"):
    client_guid: t.uint64
    seq: t.int64
    x: t.float64
    y: t.float64
    width: t.float64
    height: t.float64
    stamp: Time_
    frame_id: str


@dataclass
class Reinit_Response_(IdlStruct, typename="bevt_msgs::srv::dds_::Reinit_Response_"):
    client_guid: t.uint64
    seq: t.int64
    success: bool
    message: str


def emit(obj):
    print(json.dumps(obj), flush=True)


meta = json.loads((FRAMES / "meta.json").read_text())
W, H, N = meta["width"], meta["height"], meta["count"]

dp = DomainParticipant(DOMAIN)
reliable = Qos(Policy.Reliability.Reliable(max_blocking_time=duration(seconds=1)), Policy.History.KeepLast(50))
best_effort = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1))
img_w = DataWriter(dp, Topic(dp, "rt/image_raw", Image_), qos=best_effort)
det_r = DataReader(dp, Topic(dp, "rt/detections", Detection2DArray_), qos=reliable)
req_w = DataWriter(dp, Topic(dp, "rq/reinitRequest", Reinit_Request_), qos=reliable)
rep_r = DataReader(dp, Topic(dp, "rr/reinitReply", Reinit_Response_), qos=reliable)

deadline = time.time() + 20
while time.time() < deadline:
    if all(e.get_publication_matched_status().current_count > 0 for e in (img_w, req_w)) and all(
        e.get_subscription_matched_status().current_count > 0 for e in (det_r, rep_r)
    ):
        break
    time.sleep(0.05)
else:
    emit({"error": "no match with the node within 20 s"})
    sys.exit(3)
time.sleep(0.5)

stamp_of = {}
frame_of_stamp = {}


def publish(i):
    raw = (FRAMES / f"frame_{i:05d}.rgb").read_bytes()
    now = time.time_ns()
    st = Time_(sec=now // 1_000_000_000, nanosec=now % 1_000_000_000)
    stamp_of[i] = st
    frame_of_stamp[(st.sec, st.nanosec)] = i
    img_w.write(Image_(header=Header_(stamp=st, frame_id="cyclone_camera"), height=H, width=W,
                       encoding="rgb8", is_bigendian=0, step=W * 3, data=list(raw)))


def collect():
    for s in det_r.take(N=100):
        if not isinstance(s, Detection2DArray_) or not s.detections:
            continue
        d = s.detections[0]
        key = (s.header.stamp.sec, s.header.stamp.nanosec)
        b = d.bbox
        emit({"frame": frame_of_stamp.get(key, -1),
              "box": [b.center.position.x - b.size_x / 2, b.center.position.y - b.size_y / 2, b.size_x, b.size_y],
              "score": d.results[0].hypothesis.score if d.results else None})


# Frame 0 until the node has it, then reinit on frame 0's stamp (retrying: first samples
# may be lost while discovery settles).
guid = random.getrandbits(63)
reply = None
for attempt in range(20):
    if attempt % 4 == 0:
        publish(0)
        time.sleep(0.3)
    x, y, w, h = meta["init"]
    st = stamp_of[0]
    req_w.write(Reinit_Request_(client_guid=guid, seq=attempt + 1, x=x, y=y, width=w, height=h, stamp=st, frame_id=""))
    end = time.time() + 0.5
    while time.time() < end and reply is None:
        for r in rep_r.take(N=10):
            if isinstance(r, Reinit_Response_) and r.client_guid == guid:
                reply = r
        time.sleep(0.01)
    if reply is not None and reply.success:
        break
    reply = None
emit({"reinit": None if reply is None else {"success": reply.success, "message": reply.message}})
if reply is None:
    sys.exit(4)

period = 1.0 / RATE
nxt = time.time()
for i in range(1, N):
    publish(i)
    collect()
    nxt += period
    time.sleep(max(0.0, nxt - time.time()))
end = time.time() + 2
while time.time() < end:
    collect()
    time.sleep(0.05)
