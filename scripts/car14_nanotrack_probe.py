#!/usr/bin/env python3
"""Does NanoTrack v2 (a tracking-trained Siamese net) single out car14's returned car?

README "Confidence, lost state and re-detection" (issue 8). The car leaves the view at
frame 273 and re-enters at ~299, ~370 px left, smaller and seen from the other side. For
every frame of 274-345 (frames 274-298: car absent) the whole frame is tiled with NanoTrack
search crops (255x255 from a square of side 2*sz, as OpenCV's TrackerNano crops) at three
scales of the template's context side sz, and the head's foreground logit margin (output1
channel 1 - channel 0; softmax probability = 1/(1+exp(-margin)), which saturates) is taken
at every grid point. Printed per frame and template: the best score of a
grid point whose predicted box centre is within 12 px of the true centre ("car"), the best
score of any prediction at least 40 px from it ("else"), and the car's rank among all
predictions (grid points merged within 20 px). Frames without the car print only "else":
the false-alarm level a threshold must clear.

Templates (127x127, NanoTrack's context): frame 1 (seen from above) and frame 265 (the
last frames before the exit; ground-truth boxes, an upper bound on what the tracker knows).

Run: .venv/bin/python scripts/car14_nanotrack_probe.py [dataset root] [models dir]
(opencv from scripts/requirements-peers.txt; the network runs in OpenCV's dnn module).
"""
import math
import sys

import cv2
import numpy as np

ROOT = sys.argv[1] if len(sys.argv) > 1 else "../shared/datasets/uav123_10fps_dev"
MODELS = sys.argv[2] if len(sys.argv) > 2 else "../shared/models/nanotrack"
GT = [line.strip().split(",") for line in open(f"{ROOT}/anno/car14.txt")]
SCALES = (1.0, 0.8, 0.64)


def img(f):
    return cv2.imread(f"{ROOT}/data_seq/car14/{f:06d}.jpg")


def box(f):
    return [float(v) for v in GT[f - 1]]


def context_side(w, h):
    p = 0.5 * (w + h)
    return math.sqrt((w + p) * (h + p))


def crop(im, cx, cy, side, out, mean):
    """Square of `side` px centred on (cx, cy), outside filled with `mean`, resized to out."""
    s = out / side
    m = np.array([[s, 0, out / 2 - s * cx], [0, s, out / 2 - s * cy]], np.float32)
    return cv2.warpAffine(im, m, (out, out), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=mean)


def blob(patch):
    rgb = cv2.cvtColor(patch, cv2.COLOR_BGR2RGB).astype(np.float32)
    return rgb.transpose(2, 0, 1)[None]


class Nano:
    def __init__(self):
        self.backbone = cv2.dnn.readNet(f"{MODELS}/nanotrackv2_backbone_sim.onnx")
        self.head = cv2.dnn.readNet(f"{MODELS}/nanotrackv2_head_sim.onnx")

    def features(self, x):
        self.backbone.setInput(x, "input")
        return self.backbone.forward("output").copy()

    def score(self, zf, xf):
        self.head.setInput(zf, "input1")
        self.head.setInput(xf, "input2")
        cls, loc = self.head.forward(["output1", "output2"])
        return cls[0, 1] - cls[0, 0], loc[0]


GRID = (np.arange(16) - 8) * 16 + 127


def scan(nano, zfs, im, side, mean):
    """Per template, all predictions over the frame: rows (score, centre x, centre y), search
    side 2*side, tiles 0.75 of a crop apart."""
    h, w = im.shape[:2]
    s_crop = 2 * side
    step = 0.75 * s_crop
    k = s_crop / 255.0
    preds = [[] for _ in zfs]
    ys = np.arange(s_crop * 0.35, h - s_crop * 0.35 + step, step)
    xs = np.arange(s_crop * 0.35, w - s_crop * 0.35 + step, step)
    for cy in ys:
        for cx in xs:
            xf = nano.features(blob(crop(im, cx, cy, s_crop, 255, mean)))
            for n, zf in enumerate(zfs):
                sc, loc = nano.score(zf, xf)
                px = GRID[None, :] + (loc[2] - loc[0]) / 2
                py = GRID[:, None] + (loc[3] - loc[1]) / 2
                preds[n].append(np.stack([sc.ravel(), (cx + (px - 127.5) * k).ravel(),
                                          (cy + (py - 127.5) * k).ravel()], axis=1))
    return [np.concatenate(p) for p in preds]


def merged_rank(preds, car_score, cx, cy):
    """Rank of car_score among predictions >= 40 px from the car, greedy-merged within 20 px."""
    far = preds[np.hypot(preds[:, 1] - cx, preds[:, 2] - cy) >= 40]
    far = far[np.argsort(-far[:, 0])]
    kept = []
    for s, x, y in far:
        if s <= car_score:
            break
        if all(math.hypot(x - a, y - b) >= 20 for a, b in kept):
            kept.append((x, y))
    return len(kept) + 1


def main():
    nano = Nano()
    templates = {}
    for f in (1, 265):
        im = img(f)
        x, y, w, h = box(f)
        sz = context_side(w, h)
        mean = tuple(float(v) for v in im.reshape(-1, 3).mean(axis=0))
        templates[f] = nano.features(blob(crop(im, x + w / 2, y + h / 2, sz, 127, mean)))
    x, y, w, h = box(270)
    side0 = context_side(w, h)
    print(f"search sides 2*sz, sz = {side0:.1f} px (box of frame 270) x {SCALES}")
    print("frame   " + "   ".join(f"T{f}: car / else (rank)" for f in templates))
    for f in list(range(276, 298, 6)) + list(range(299, 346, 3)):
        im = img(f)
        mean = tuple(float(v) for v in im.reshape(-1, 3).mean(axis=0))
        b = box(f)
        present = not any(math.isnan(v) for v in b)
        per_scale = [scan(nano, list(templates.values()), im, side0 * s, mean) for s in SCALES]
        cols = []
        for n in range(len(templates)):
            preds = np.concatenate([ps[n] for ps in per_scale])
            if present:
                cx, cy = b[0] + b[2] / 2, b[1] + b[3] / 2
                d = np.hypot(preds[:, 1] - cx, preds[:, 2] - cy)
                car = preds[d < 12, 0].max() if (d < 12).any() else -99.0
                other = preds[d >= 40, 0].max()
                cols.append(f"   {car:6.2f} / {other:6.2f} ({merged_rank(preds, car, cx, cy):3d})")
            else:
                cols.append(f"        - / {preds[:, 0].max():6.2f}      ")
        print(f"{f:5d}" + "".join(cols), flush=True)

if __name__ == "__main__":
    main()
