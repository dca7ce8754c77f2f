"""Writes rosbag2 bags for the replay tests with the Python `rosbags` package (an
implementation independent of ours), from frames the Rust test wrote:

    $(scripts/python-env.sh) scripts/make_test_bags.py FRAMES_DIR OUT_DIR

FRAMES_DIR holds meta.json ({"width", "height", "count", "stamp0_ns", "period_ns",
"enc_frames", "raw": bool}), frame_NNNNN.jpg and, when "raw", frame_NNNNN.rgb (packed rgb8).

With "raw" it writes, each as `Writer(version=9)`:
- OUT_DIR/mcap_bag (mcap storage): /camera/image_raw (rgb8), /camera/image_raw/compressed
  (jpeg), /camera/<enc> for bgr8, mono8, rgba8, bgra8, yuv422, yuv422_yuy2 (the first
  enc_frames frames), /chatter (std_msgs/msg/String), the bad topics /bad/encoding
  (bayer_rggb8), /bad/step (step disagrees with the data), /bad/size_change (half size
  after enc_frames frames), /bad/order (two stamps swapped), and /empty (no messages);
- OUT_DIR/db3_bag (sqlite3 storage): /camera/image_raw, /camera/image_raw/compressed, /empty;
- OUT_DIR/no_topics (mcap storage, nothing recorded).
Without "raw" (a real sequence's JPEG files): OUT_DIR/seq_bag (mcap) with
/camera/image_raw/compressed only.
"""
import json
import pathlib
import sys

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
Image = ts.types["sensor_msgs/msg/Image"]
CompressedImage = ts.types["sensor_msgs/msg/CompressedImage"]
Header = ts.types["std_msgs/msg/Header"]
Time = ts.types["builtin_interfaces/msg/Time"]
String = ts.types["std_msgs/msg/String"]


def header(ns):
    return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000),
                  frame_id="camera")


def image(ns, arr, encoding, step=None):
    h = arr.shape[0]
    row = arr.reshape(h, -1)
    # 4:2:2 packs two bytes per pixel into (H, 2W) arrays.
    w = row.shape[1] // 2 if encoding.startswith("yuv422") else arr.shape[1]
    return Image(header=header(ns), height=h, width=w, encoding=encoding, is_bigendian=0,
                 step=row.shape[1] if step is None else step,
                 data=np.ascontiguousarray(row).reshape(-1).astype(np.uint8))


def yuv422(rgb, order):
    """Packs rgb (H, W, 3) into 4:2:2 bytes in `order` ('UYVY' or 'YUYV'), BT.601 studio."""
    f = rgb.astype(np.float64)
    y = 16 + (65.481 * f[..., 0] + 128.553 * f[..., 1] + 24.966 * f[..., 2]) / 255
    u = 128 + (-37.797 * f[..., 0] - 74.203 * f[..., 1] + 112.0 * f[..., 2]) / 255
    v = 128 + (112.0 * f[..., 0] - 93.786 * f[..., 1] - 18.214 * f[..., 2]) / 255
    y, u, v = (np.clip(np.round(c), 0, 255).astype(np.uint8) for c in (y, u, v))
    uu = ((u[:, 0::2].astype(np.uint16) + u[:, 1::2]) // 2).astype(np.uint8)
    vv = ((v[:, 0::2].astype(np.uint16) + v[:, 1::2]) // 2).astype(np.uint8)
    y0, y1 = y[:, 0::2], y[:, 1::2]
    parts = {"U": uu, "V": vv}
    seq = [parts[c] if c in parts else None for c in order]
    ys = iter([y0, y1])
    seq = [s if s is not None else next(ys) for s in seq]
    return np.stack(seq, axis=-1).reshape(rgb.shape[0], rgb.shape[1] * 2)


def write(w, conn, msg, ns):
    w.write(conn, ns, ts.serialize_cdr(msg, msg.__msgtype__))


def main():
    frames, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    meta = json.loads((frames / "meta.json").read_text())
    wd, ht, n = meta["width"], meta["height"], meta["count"]
    t0, dt = meta["stamp0_ns"], meta["period_ns"]
    k = meta.get("enc_frames", 0)
    out.mkdir(parents=True, exist_ok=True)
    jpg = [(frames / f"frame_{i:05d}.jpg").read_bytes() for i in range(n)]

    def compressed(i):
        return CompressedImage(header=header(t0 + i * dt), format="jpeg",
                               data=np.frombuffer(jpg[i], dtype=np.uint8))

    if not meta.get("raw", True):
        with Writer(out / "seq_bag", version=9, storage_plugin=StoragePlugin.MCAP) as w:
            c = w.add_connection("/camera/image_raw/compressed", CompressedImage.__msgtype__,
                                 typestore=ts)
            for i in range(n):
                write(w, c, compressed(i), t0 + i * dt)
        return

    rgb = [np.frombuffer((frames / f"frame_{i:05d}.rgb").read_bytes(), dtype=np.uint8)
           .reshape(ht, wd, 3) for i in range(n)]
    encodings = {
        "bgr8": lambda a: a[..., ::-1],
        "mono8": lambda a: np.round(a @ np.array([0.299, 0.587, 0.114])).astype(np.uint8),
        "rgba8": lambda a: np.concatenate([a, np.full(a.shape[:2] + (1,), 255, np.uint8)], -1),
        "bgra8": lambda a: np.concatenate([a[..., ::-1], np.full(a.shape[:2] + (1,), 255, np.uint8)], -1),
        "yuv422": lambda a: yuv422(a, "UYVY"),
        "yuv422_yuy2": lambda a: yuv422(a, "YUYV"),
    }

    def record(path, plugin, full):
        with Writer(path, version=9, storage_plugin=plugin) as w:
            raw = w.add_connection("/camera/image_raw", Image.__msgtype__, typestore=ts)
            cmp = w.add_connection("/camera/image_raw/compressed", CompressedImage.__msgtype__,
                                   typestore=ts)
            w.add_connection("/empty", Image.__msgtype__, typestore=ts)
            extra = {}
            if full:
                for e in encodings:
                    extra[e] = w.add_connection(f"/camera/{e}", Image.__msgtype__, typestore=ts)
                chatter = w.add_connection("/chatter", String.__msgtype__, typestore=ts)
                bad = {b: w.add_connection(f"/bad/{b}", Image.__msgtype__, typestore=ts)
                       for b in ["encoding", "step", "size_change", "order"]}
            for i in range(n):
                ns = t0 + i * dt
                write(w, raw, image(ns, rgb[i], "rgb8"), ns)
                write(w, cmp, compressed(i), ns)
                if not full:
                    continue
                if i < k:
                    for e, f in encodings.items():
                        write(w, extra[e], image(ns, f(rgb[i]), e), ns)
                    write(w, chatter, String(data=f"frame {i}"), ns)
                if i < 3:
                    write(w, bad["encoding"], image(ns, rgb[i][..., 0], "bayer_rggb8"), ns)
                    write(w, bad["step"], image(ns, rgb[i], "rgb8", step=wd * 3 + 1), ns)
                if i < 2 * k:
                    a = rgb[i] if i < k else np.ascontiguousarray(rgb[i][: ht // 2, : wd // 2])
                    write(w, bad["size_change"], image(ns, a, "rgb8"), ns)
                if i < k:
                    # Frames 3 and 4 swap stamps: frame 4 (recorded after 3) is older.
                    j = {3: 4, 4: 3}.get(i, i)
                    write(w, bad["order"], image(t0 + j * dt, rgb[i], "rgb8"), ns)

    record(out / "mcap_bag", StoragePlugin.MCAP, True)
    record(out / "db3_bag", StoragePlugin.SQLITE3, False)
    with Writer(out / "no_topics", version=9, storage_plugin=StoragePlugin.MCAP):
        pass


if __name__ == "__main__":
    main()
