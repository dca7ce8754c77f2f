"""A real ROS 2 client against the node: rclpy over rcl and rmw_fastrtps_cpp (Fast DDS 3),
from the PyPI ROS wheels (scripts/requirements-ros.txt), as `ros2 param` / `ros2 topic` and a
ROS 2 camera use them.

Usage: rclpy_peer.py NODE (ROS_DOMAIN_ID and the discovery variables come from the environment).
One JSON command per line on stdin, one JSON answer per line on stdout:

  {"cmd": "graph", "timeout": S}            -> {"nodes": [...], "topics": [...], "services": [...]}
      waits until NODE and its parameter services are in the ROS graph (error on timeout)
  {"cmd": "list", "depth": D}               -> {"names": [...], "prefixes": [...]}
  {"cmd": "get", "names": [...]}            -> {"values": [...]}
  {"cmd": "describe", "names": [...]}       -> {"descriptors": [{name, type, read_only, ...}]}
  {"cmd": "set", "name": N, "value": V}     -> {"successful": b, "reason": s}
  {"cmd": "events"}                         -> {"events": [{"node", "changed": [[name, value]]}]}
  {"cmd": "camera", "topic": T, "width": W, "height": H, "rate": HZ}
      starts publishing rgb8 sensor_msgs/Image frames of a synthetic scene (a textured target
      moving over a textured background) -> {"frame_bytes": n}
  {"cmd": "camera_stop"}                    -> {"stopped": true}
  {"cmd": "truth"}                          -> {"frames": [[stamp_ns, [x, y, w, h]], ...]}
  {"cmd": "debug", "topic": T, "reliable": b}
      -> {"received": n, "kept": k, "intact": i, "checked": [...]}
      debug images received so far (subscribed at the first call, reliable by default as
      RViz does); of the last k kept, "intact" counts those whose size fields agree with
      their data and whose pixels equal the published frame of the same stamp outside the
      drawn box (the overlay)
  {"cmd": "quit"}

A service call that gets no reply within 10 s answers {"error": "..."}.
"""

import json
import sys
import threading
import time

import numpy as np
import rclpy
from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from sensor_msgs.msg import Image

CALL_TIMEOUT_S = 10.0


def to_value(v):
    pv = ParameterValue()
    if isinstance(v, bool):
        pv.type, pv.bool_value = ParameterType.PARAMETER_BOOL, v
    elif isinstance(v, int):
        pv.type, pv.integer_value = ParameterType.PARAMETER_INTEGER, v
    elif isinstance(v, float):
        pv.type, pv.double_value = ParameterType.PARAMETER_DOUBLE, v
    elif isinstance(v, str):
        pv.type, pv.string_value = ParameterType.PARAMETER_STRING, v
    else:
        raise ValueError(f"unsupported value {v!r}")
    return pv


def from_value(p):
    t = p.type
    return {
        ParameterType.PARAMETER_NOT_SET: lambda: {"type": "not_set"},
        ParameterType.PARAMETER_BOOL: lambda: p.bool_value,
        ParameterType.PARAMETER_INTEGER: lambda: p.integer_value,
        ParameterType.PARAMETER_DOUBLE: lambda: p.double_value,
        ParameterType.PARAMETER_STRING: lambda: p.string_value,
        ParameterType.PARAMETER_BYTE_ARRAY: lambda: list(p.byte_array_value),
        ParameterType.PARAMETER_BOOL_ARRAY: lambda: list(p.bool_array_value),
        ParameterType.PARAMETER_INTEGER_ARRAY: lambda: list(p.integer_array_value),
        ParameterType.PARAMETER_DOUBLE_ARRAY: lambda: list(p.double_array_value),
        ParameterType.PARAMETER_STRING_ARRAY: lambda: list(p.string_array_value),
    }[t]()


class Scene:
    """A deterministic scene: a 48x40 target of random colour blocks on a background of
    random 16-pixel blocks, moving on an ellipse. Frame t and its box are a function of t
    alone."""

    def __init__(self, width, height):
        self.w, self.h = width, height
        rng = np.random.default_rng(7)
        coarse = rng.integers(40, 200, size=(height // 16 + 2, width // 16 + 2, 3))
        bg = np.kron(coarse, np.ones((16, 16, 1)))[:height, :width]
        self.bg = bg.astype(np.uint8)
        tw, th = 48, 40
        # Random 4x4-pixel blocks in saturated colours: textured, not periodic (a checker
        # lets a correlation filter lock one period off).
        blocks = rng.integers(0, 2, size=(th // 4, tw // 4, 3)) * 255
        self.target = np.kron(blocks, np.ones((4, 4, 1))).astype(np.uint8)
        self.tw, self.th = tw, th

    def box(self, t):
        cx = self.w / 2 + 0.25 * self.w * np.cos(t / 40.0)
        cy = self.h / 2 + 0.20 * self.h * np.sin(t / 40.0)
        return [int(round(cx - self.tw / 2)), int(round(cy - self.th / 2)), self.tw, self.th]

    def frame(self, t):
        img = self.bg.copy()
        x, y, w, h = self.box(t)
        img[y:y + h, x:x + w] = self.target
        return img


class Peer:
    def __init__(self, target):
        self.target = target  # "/bevt_node"
        self.node = Node("bevt_rclpy_peer")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.events = []
        self.frames = {}  # stamp_ns -> (t, box)
        self.scene = None
        self.debug_msgs = []
        self.debug_sub = None
        self.stopping = threading.Event()
        self.camera_thread = None
        self.clients = {
            "list": self.node.create_client(ListParameters, f"{target}/list_parameters"),
            "get": self.node.create_client(GetParameters, f"{target}/get_parameters"),
            "describe": self.node.create_client(DescribeParameters,
                                                f"{target}/describe_parameters"),
            "set": self.node.create_client(SetParameters, f"{target}/set_parameters"),
        }
        self.node.create_subscription(ParameterEvent, "/parameter_events", self.on_event,
                                      QoSProfile(depth=1000,
                                                 reliability=ReliabilityPolicy.RELIABLE))
        self.spin = threading.Thread(target=self.executor.spin, daemon=True)
        self.spin.start()

    def on_event(self, ev):
        with self.lock:
            self.events.append({
                "node": ev.node,
                "changed": [[p.name, from_value(p.value)] for p in ev.changed_parameters],
            })

    def call(self, kind, req):
        client = self.clients[kind]
        if not client.wait_for_service(timeout_sec=CALL_TIMEOUT_S):
            raise TimeoutError(f"{kind}: service not available in {CALL_TIMEOUT_S} s")
        fut = client.call_async(req)
        end = time.monotonic() + CALL_TIMEOUT_S
        while not fut.done():
            if time.monotonic() > end:
                client.remove_pending_request(fut)
                raise TimeoutError(f"{kind}: no reply in {CALL_TIMEOUT_S} s")
            time.sleep(0.01)
        return fut.result()

    def graph(self, timeout):
        end = time.monotonic() + timeout
        want = f"{self.target}/list_parameters"
        while True:
            nodes = ["/".join(["" if ns == "/" else ns, n]) for n, ns in
                     self.node.get_node_names_and_namespaces()]
            services = [n for n, _ in self.node.get_service_names_and_types()]
            topics = [n for n, _ in self.node.get_topic_names_and_types()]
            if self.target in nodes and want in services:
                return {"nodes": nodes, "topics": topics, "services": services}
            if time.monotonic() > end:
                raise TimeoutError(f"{self.target} not in the graph after {timeout} s: "
                                   f"nodes {nodes}, services {services}")
            time.sleep(0.1)

    def camera(self, topic, width, height, rate):
        self.scene = Scene(width, height)
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST)
        pub = self.node.create_publisher(Image, topic, qos)
        frame_bytes = width * height * 3

        def run():
            t = 0
            while not self.stopping.is_set():
                img = self.scene.frame(t)
                msg = Image()
                now = time.time_ns()
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
                msg.header.frame_id = "cam"
                msg.height, msg.width = height, width
                msg.encoding, msg.is_bigendian, msg.step = "rgb8", 0, width * 3
                msg.data = img.tobytes()
                with self.lock:
                    self.frames[now] = (t, self.scene.box(t))
                pub.publish(msg)
                t += 1
                self.stopping.wait(1.0 / rate)

        self.camera_thread = threading.Thread(target=run, daemon=True)
        self.camera_thread.start()
        return {"frame_bytes": frame_bytes}

    def subscribe_debug(self, topic, reliable):
        if self.debug_sub is None:
            # RViz's and rclpy's default: reliable, keep last 10.
            qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable
                             else ReliabilityPolicy.BEST_EFFORT)

            def on_debug(msg):
                with self.lock:
                    self.debug_total += 1
                    self.debug_msgs.append(msg)
                    del self.debug_msgs[:-20]

            self.debug_total = 0
            self.debug_sub = self.node.create_subscription(Image, topic, on_debug, qos)

    def debug(self, topic, reliable):
        self.subscribe_debug(topic, reliable)
        with self.lock:
            msgs = list(self.debug_msgs)
            total = self.debug_total
            frames = dict(self.frames)
        checked = []
        for m in msgs:
            stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            data = np.frombuffer(bytes(m.data), dtype=np.uint8)
            sizes_ok = (m.encoding == "rgb8" and m.step == m.width * 3
                        and len(data) == m.step * m.height)
            entry = {"stamp": stamp, "width": m.width, "height": m.height,
                     "bytes": len(data), "sizes_ok": sizes_ok}
            if sizes_ok and stamp in frames and self.scene is not None:
                t, _ = frames[stamp]
                sent = self.scene.frame(t)
                got = data.reshape(m.height, m.width, 3)
                equal = np.all(got == sent, axis=-1)
                entry["equal_fraction"] = float(equal.mean())
            checked.append(entry)
        intact = sum(1 for c in checked if c.get("equal_fraction", 0.0) > 0.97)
        return {"received": total, "kept": len(msgs), "intact": intact, "checked": checked}


def main():
    target = sys.argv[1]
    rclpy.init()
    peer = Peer(target)
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        if not line.strip():
            continue
        cmd = json.loads(line)
        try:
            c = cmd["cmd"]
            if c == "quit":
                break
            elif c == "graph":
                out = peer.graph(float(cmd.get("timeout", 30)))
            elif c == "list":
                r = peer.call("list", ListParameters.Request(depth=int(cmd.get("depth", 0))))
                out = {"names": list(r.result.names), "prefixes": list(r.result.prefixes)}
            elif c == "get":
                r = peer.call("get", GetParameters.Request(names=cmd["names"]))
                out = {"values": [from_value(v) for v in r.values]}
            elif c == "describe":
                r = peer.call("describe", DescribeParameters.Request(names=cmd["names"]))
                out = {"descriptors": [{
                    "name": d.name, "type": d.type, "read_only": d.read_only,
                    "dynamic_typing": d.dynamic_typing, "description": d.description,
                    "floating_point_range": [[x.from_value, x.to_value, x.step]
                                             for x in d.floating_point_range],
                    "integer_range": [[x.from_value, x.to_value, x.step]
                                      for x in d.integer_range],
                } for d in r.descriptors]}
            elif c == "set":
                p = Parameter(name=cmd["name"], value=to_value(cmd["value"]))
                r = peer.call("set", SetParameters.Request(parameters=[p]))
                out = {"successful": r.results[0].successful, "reason": r.results[0].reason}
            elif c == "events":
                with peer.lock:
                    out = {"events": list(peer.events)}
            elif c == "camera":
                out = peer.camera(cmd["topic"], int(cmd["width"]), int(cmd["height"]),
                                  float(cmd["rate"]))
            elif c == "camera_stop":
                peer.stopping.set()
                if peer.camera_thread is not None:
                    peer.camera_thread.join()
                out = {"stopped": True}
            elif c == "truth":
                with peer.lock:
                    out = {"frames": [[k, v[1]] for k, v in sorted(peer.frames.items())]}
            elif c == "debug":
                out = peer.debug(cmd["topic"], bool(cmd.get("reliable", True)))
            else:
                out = {"error": f"unknown command {c}"}
        except Exception as e:  # answered, so the test prints it
            out = {"error": f"{type(e).__name__}: {e}"}
        print(json.dumps(out), flush=True)
    peer.stopping.set()
    if peer.camera_thread is not None:
        peer.camera_thread.join()
    peer.executor.shutdown()
    peer.spin.join()
    peer.node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
