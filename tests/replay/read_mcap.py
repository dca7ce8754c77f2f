"""Reads an MCAP written by `bevt replay` with the independent Python readers (`mcap` +
`mcap-ros2-support`, which decode every message from the schema in the file) and prints
a JSON summary: profile, per-topic schema name/encoding/message encoding and count, and
the decoded detections, statuses and annotations in order.

    $(scripts/python-env.sh) tests/replay/read_mcap.py OUT.mcap
"""
import json
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    header = reader.get_header()
    out = {"profile": header.profile, "topics": {}, "detections": [], "status": [],
           "annotations": []}
    for schema, channel, message, ros in reader.iter_decoded_messages():
        t = out["topics"].setdefault(channel.topic, {
            "schema": schema.name, "schema_encoding": schema.encoding,
            "message_encoding": channel.message_encoding, "count": 0})
        t["count"] += 1
        if channel.topic == "/detections":
            stamp = ros.header.stamp.sec * 1_000_000_000 + ros.header.stamp.nanosec
            dets = [{"id": d.id, "score": d.results[0].hypothesis.score,
                     "cx": d.bbox.center.position.x, "cy": d.bbox.center.position.y,
                     "w": d.bbox.size_x, "h": d.bbox.size_y,
                     "stamp": d.header.stamp.sec * 1_000_000_000 + d.header.stamp.nanosec}
                    for d in ros.detections]
            out["detections"].append({"stamp": stamp, "frame_id": ros.header.frame_id,
                                      "log_time": message.log_time, "dets": dets})
        elif channel.topic == "/track_status":
            out["status"].append({"state": ros.state, "track_id": ros.track_id,
                                  "x": ros.x, "y": ros.y, "confidence": ros.confidence})
        elif channel.topic == "/track_annotations":
            out["annotations"].append({"points": [[[p.x, p.y] for p in a.points]
                                                  for a in ros.points],
                                       "texts": [t.text for t in ros.texts]})
print(json.dumps(out))
