#!/usr/bin/env python3
"""Does NanoTrack v2's head find the target in search crops larger than its own 255 pixels?

docs/benchmarks.md "Larger verifier tiles" (issue 19 §2, `redetection.verifier_tile_cells`).
The backbone has six squeeze-and-excitation blocks and each head branch a channel attention,
so a crop of N x N cells (16N - 1 pixels at NanoTrack's resolution: 255 px per twice the
template's context side) is not 16-cell tiles cut out of one map: it is another input the
network was not trained on. Per dev sequence the template is frame 1's truth box (127 px, as
the verifier's); on every 5th frame with a truth box the target is put at a random grid
position of [1.5, N - 2.5] cells of a crop of N cells (the same position draw for every N is
not needed: positions are uniform over each crop's own grid) and the head's foreground logit
margin (output1 channel 1 - channel 0) is read. Printed per sequence and N: the hit rate (the
best margin within 1.5 cells of the target at or above BAR, the verifier's 5.0), its mean,
false hits per 256 grid points (points 3 or more cells from the target at or above BAR: a
rate per area, comparable between sizes) and the share of crops with a false hit.

The networks run on ONNX Runtime from Python, crops with OpenCV's INTER_LINEAR and a
replicated border (what `image::sample_bilinear` computes), the head's reshape to 16 x 16
rewritten to N x N (as `redetect::nano::head_for_cells`).

Run: python3 -m venv target/venv-probe && target/venv-probe/bin/pip install
     opencv-python-headless==5.1.0.95 onnx==1.23.2 onnxruntime==1.31.1 numpy==2.4.6
     target/venv-probe/bin/python scripts/verifier_tile_probe.py [N ...] (default 16 24 32)
Environment: DATASET (default ../shared/datasets/uav123_10fps_dev).
"""
import collections
import json
import math
import os
import random
import sys

import cv2
import numpy as np
import onnx
import onnxruntime as ort
from onnx import numpy_helper

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.environ.get("DATASET", os.path.join(HERE, "../../shared/datasets/uav123_10fps_dev"))
MODELS = os.path.join(HERE, "../models/nanotrack")
BAR = 5.0
OPTS = ort.SessionOptions()
OPTS.intra_op_num_threads = 1
CPU = ["CPUExecutionProvider"]
BACKBONE = ort.InferenceSession(f"{MODELS}/nanotrackv2_backbone_sim_dyn.onnx", OPTS, providers=CPU)
HEADS = {}


def head(n):
    """The head for N x N search features: its [1, -1, 16, 16] reshape and input2 resized."""
    if n not in HEADS:
        m = onnx.load(f"{MODELS}/nanotrackv2_head_sim.onnx")
        for t in m.graph.initializer:
            a = numpy_helper.to_array(t)
            if a.dtype == np.int64 and list(a) == [1, -1, 16, 16]:
                t.CopyFrom(numpy_helper.from_array(np.array([1, -1, n, n], np.int64), t.name))
        m.graph.ClearField("value_info")
        for i in m.graph.input:
            if i.name == "input2":
                d = i.type.tensor_type.shape.dim
                d[2].dim_value = n
                d[3].dim_value = n
        HEADS[n] = ort.InferenceSession(m.SerializeToString(), OPTS, providers=CPU)
    return HEADS[n]


def context_side(w, h):
    p = 0.5 * (w + h)
    return math.sqrt((w + p) * (h + p))


def crop(im, cx, cy, side, out):
    """The square of `side` px at (cx, cy), border replicated, resized to out x out (RGB)."""
    s = out / side
    m = np.array([[s, 0, out / 2 - s * cx], [0, s, out / 2 - s * cy]], np.float32)
    p = cv2.warpAffine(im, m, (out, out), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return cv2.cvtColor(p, cv2.COLOR_BGR2RGB).astype(np.float32).transpose(2, 0, 1)[None]


def features(x):
    return BACKBONE.run(["output"], {"input": x})[0]


def main():
    sizes = [int(a) for a in sys.argv[1:]] or [16, 24, 32]
    rng = random.Random(7)
    total = {n: collections.Counter() for n in sizes}
    for s in json.load(open(f"{ROOT}/sequences.json"))["sequences"]:
        gt = [line.strip().split(",") for line in open(f"{ROOT}/{s['anno']}")]

        def img(f):
            name = f"{f + s['start_frame']:0{s['nz']}d}.{s['ext']}"
            return cv2.imread(f"{ROOT}/{s['img_dir']}/{name}")

        x, y, w, h = map(float, gt[0])
        sz = context_side(w, h)
        zf = features(crop(img(0), x + w / 2, y + h / 2, sz, 127))
        per = {n: collections.Counter() for n in sizes}
        for f in range(5, len(gt), 5):
            try:
                x, y, w, h = map(float, gt[f])
            except ValueError:
                continue
            if not all(map(math.isfinite, (x, y, w, h))) or w <= 0 or h <= 0:
                continue
            im = img(f)
            cx, cy = x + w / 2, y + h / 2
            for n in sizes:
                out = 16 * n - 1
                side = 2 * sz * out / 255
                px = side / out
                gj, gi = rng.uniform(1.5, n - 2.5), rng.uniform(1.5, n - 2.5)
                # Grid point j sits at crop pixel 16 j - 1.
                tx, ty = 16 * gj - 1, 16 * gi - 1
                ccx, ccy = cx - (tx - out / 2) * px, cy - (ty - out / 2) * px
                xf = features(crop(im, ccx, ccy, side, out))
                cls = head(n).run(["output1"], {"input1": zf, "input2": xf})[0]
                margin = cls[0, 1] - cls[0, 0]
                cols, rows = np.meshgrid(np.arange(n), np.arange(n))
                d = np.hypot(cols - gj, rows - gi)
                near = float(margin[d <= 1.5].max())
                far = margin[d >= 3.0]
                c = per[n]
                c["crops"] += 1
                c["hit"] += near >= BAR
                c["near"] += near
                c["points"] += far.size
                c["false"] += int((far >= BAR).sum())
                c["false_crops"] += int(far.max() >= BAR)
        for n in sizes:
            total[n].update(per[n])
            report(s["name"], n, per[n])
    for n in sizes:
        report("ALL", n, total[n])


def report(name, n, c):
    k = max(c["crops"], 1)
    print(f"{name:>12} N={n:2d} crops {c['crops']:4d} hit {c['hit'] / k:.3f} "
          f"mean near {c['near'] / k:5.2f} false per 256 points "
          f"{256 * c['false'] / max(c['points'], 1):.3f} crops with a false hit "
          f"{c['false_crops'] / k:.3f}", flush=True)


if __name__ == "__main__":
    main()
