"""Writes msgs/tests/golden/*.cdr: reference CDR bytes (little endian, with the 4-byte
encapsulation header) of sample messages, serialised by the `rosbags` package -- an
implementation independent of ours. (Service halves are registered under msg/ names: rosbags
names only message types; the CDR layout is the same.) msgs/tests/golden.rs builds the same samples in Rust
and must produce identical bytes.

    $(scripts/python-env.sh) scripts/cdr_golden.py
"""
import pathlib
import numpy as np
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

root = pathlib.Path(__file__).resolve().parent.parent
out = root / "msgs" / "tests" / "golden"
out.mkdir(parents=True, exist_ok=True)

ts = get_typestore(Stores.ROS2_HUMBLE)
extra = {}
vision = {
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose":
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/Detection2D":
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox2D bbox\nstring id\n",
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
    # foxglove_msgs as released for ROS 2 (bevt replay's overlay), from msgs/src/ros2msg.rs.
    "foxglove_msgs/msg/Point2": "float64 x\nfloat64 y\n",
    "foxglove_msgs/msg/Color": "float64 r\nfloat64 g\nfloat64 b\nfloat64 a\n",
    "foxglove_msgs/msg/CircleAnnotation":
        "builtin_interfaces/Time timestamp\nfoxglove_msgs/Point2 position\nfloat64 diameter\n"
        "float64 thickness\nfoxglove_msgs/Color fill_color\nfoxglove_msgs/Color outline_color\n",
    "foxglove_msgs/msg/PointsAnnotation":
        "builtin_interfaces/Time timestamp\nuint8 LINE_LOOP=2\nuint8 type\nfoxglove_msgs/Point2[] points\n"
        "foxglove_msgs/Color outline_color\nfoxglove_msgs/Color[] outline_colors\n"
        "foxglove_msgs/Color fill_color\nfloat64 thickness\n",
    "foxglove_msgs/msg/TextAnnotation":
        "builtin_interfaces/Time timestamp\nfoxglove_msgs/Point2 position\nstring text\n"
        "float64 font_size\nfoxglove_msgs/Color text_color\nfoxglove_msgs/Color background_color\n",
    "foxglove_msgs/msg/ImageAnnotations":
        "foxglove_msgs/CircleAnnotation[] circles\nfoxglove_msgs/PointsAnnotation[] points\n"
        "foxglove_msgs/TextAnnotation[] texts\n",
    "std_srvs/msg/Trigger_Request": "uint8 structure_needs_at_least_one_member\n",
    "std_srvs/msg/Trigger_Response": "bool success\nstring message\n",
}
for name, text in vision.items():
    extra.update(get_types_from_msg(text, name))
extra.update(get_types_from_msg((root / "msgs/msg/TrackStatus.msg").read_text(), "bevt_msgs/msg/TrackStatus"))
req, resp = (root / "msgs/srv/Reinit.srv").read_text().split("---")
extra.update(get_types_from_msg(req, "bevt_msgs/msg/Reinit_Request"))
extra.update(get_types_from_msg(resp, "bevt_msgs/msg/Reinit_Response"))
ts.register(extra)

T = lambda n: ts.types[n]
Time = T("builtin_interfaces/msg/Time")
Header = T("std_msgs/msg/Header")
hdr = Header(stamp=Time(sec=1700000000, nanosec=123456789), frame_id="camera_optical")

samples = {
    "image": ts.types["sensor_msgs/msg/Image"](
        header=hdr, height=2, width=3, encoding="rgb8", is_bigendian=0, step=9,
        data=np.arange(18, dtype=np.uint8)),
    "compressed_image": ts.types["sensor_msgs/msg/CompressedImage"](
        header=hdr, format="jpeg", data=np.array([0xFF, 0xD8, 0xFF, 0xD9], dtype=np.uint8)),
}
P = T("geometry_msgs/msg/Point"); Q = T("geometry_msgs/msg/Quaternion")
Pose = T("geometry_msgs/msg/Pose"); PWC = T("geometry_msgs/msg/PoseWithCovariance")
pose = PWC(pose=Pose(position=P(x=0.0, y=0.0, z=0.0), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
           covariance=np.arange(36, dtype=np.float64) * 0.5)
hyp = T("vision_msgs/msg/ObjectHypothesisWithPose")(
    hypothesis=T("vision_msgs/msg/ObjectHypothesis")(class_id="target", score=0.875), pose=pose)
bbox = T("vision_msgs/msg/BoundingBox2D")(
    center=T("vision_msgs/msg/Pose2D")(position=T("vision_msgs/msg/Point2D")(x=100.5, y=50.25), theta=0.0),
    size_x=40.0, size_y=30.0)
det = T("vision_msgs/msg/Detection2D")(header=hdr, results=[hyp], bbox=bbox, id="7")
samples["detection2d_array"] = T("vision_msgs/msg/Detection2DArray")(header=hdr, detections=[det])
KV = T("diagnostic_msgs/msg/KeyValue")
DS = T("diagnostic_msgs/msg/DiagnosticStatus")
samples["diagnostic_array"] = T("diagnostic_msgs/msg/DiagnosticArray")(header=hdr, status=[DS(
    level=1, name="bevt_node: tracker", message="low consensus", hardware_id="camera",
    values=[KV(key="fps", value="30.0"), KV(key="dropped", value="2")])])
samples["track_status"] = T("bevt_msgs/msg/TrackStatus")(
    header=hdr, state=2, reason="consensus 0.15 <= 0.20", x=1.5, y=2.5, width=40.0, height=30.0,
    consensus=0.15, confidence=0.42, learned=False, peak=0.012, scale=1.25, latency_ms=4.5,
    frames_processed=100, frames_dropped=3, track_id=2)
samples["reinit_request"] = T("bevt_msgs/msg/Reinit_Request")(
    x=10.0, y=20.0, width=30.0, height=40.0, stamp=Time(sec=5, nanosec=6), frame_id="cam")
samples["reinit_response"] = T("bevt_msgs/msg/Reinit_Response")(success=True, message="ok")
samples["trigger_request"] = T("std_srvs/msg/Trigger_Request")(structure_needs_at_least_one_member=0)
samples["trigger_response"] = T("std_srvs/msg/Trigger_Response")(success=True, message="stopped")

F = lambda n: T("foxglove_msgs/msg/" + n)
green = F("Color")(r=0.0, g=1.0, b=0.25, a=1.0)
clear = F("Color")(r=0.0, g=0.0, b=0.0, a=0.0)
stamp = Time(sec=1700000000, nanosec=123456789)
samples["image_annotations"] = F("ImageAnnotations")(
    circles=[F("CircleAnnotation")(timestamp=stamp, position=F("Point2")(x=120.5, y=65.25),
                                   diameter=4.0, thickness=1.5, fill_color=green, outline_color=clear)],
    points=[F("PointsAnnotation")(timestamp=stamp, type=2,
                                  points=[F("Point2")(x=100.5, y=50.25), F("Point2")(x=140.5, y=50.25),
                                          F("Point2")(x=140.5, y=80.25), F("Point2")(x=100.5, y=80.25)],
                                  outline_color=green, outline_colors=[], fill_color=clear, thickness=2.0)],
    texts=[F("TextAnnotation")(timestamp=stamp, position=F("Point2")(x=100.5, y=48.0),
                               text="track 7 0.88", font_size=14.0, text_color=green,
                               background_color=clear)])

for name, msg in samples.items():
    data = bytes(ts.serialize_cdr(msg, msg.__msgtype__))
    (out / f"{name}.cdr").write_bytes(data)
    print(f"{name}: {len(data)} bytes")
