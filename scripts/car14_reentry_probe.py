#!/usr/bin/env python3
"""Can any appearance model from before car14's loss single out the returned car?

README "Confidence, lost state and re-detection" (issue 8). For frames 300-344 (step 4) of
UAV123@10fps car14, after the car re-enters the view, prints for two appearance cues the
best score within a few pixels of the true box against the best score elsewhere in the
frame (and the returned car's rank among all windows):

  ncc   grey normalised cross-correlation with a bank of 28 templates of the car (every
        10th frame 1-271, box x1.5 context), each resized to the true size of the returned
        car (an upper bound: the tracker does not know that size);
  hist  Bhattacharyya similarity of an 8x8x8 RGB histogram (mean over frames 1-270) over
        windows of the true size every 6 px.

Run: .venv/bin/python scripts/car14_reentry_probe.py [dataset root]
(opencv from scripts/requirements-peers.txt). Takes ~2 minutes.
"""
import sys

import cv2
import numpy as np

ROOT = sys.argv[1] if len(sys.argv) > 1 else "../shared/datasets/uav123_10fps_dev"
GT = [line.strip().split(",") for line in open(f"{ROOT}/anno/car14.txt")]
B = 8


def img(f):
    return cv2.imread(f"{ROOT}/data_seq/car14/{f:06d}.jpg")


def box(f):
    return [float(v) for v in GT[f - 1]]


def hist_index(im):
    q = (im // (256 // B)).astype(np.int32)
    return q[..., 0] * B * B + q[..., 1] * B + q[..., 2]


def main():
    bank = []
    target_hist = np.zeros(B**3)
    for f in range(1, 273):
        x, y, w, h = box(f)
        if f % 10 == 1:
            cx, cy, cw, ch = x + w / 2, y + h / 2, w * 1.5, h * 1.5
            bank.append(img(f)[int(cy - ch / 2):int(cy + ch / 2), int(cx - cw / 2):int(cx + cw / 2)])
        if f % 5 == 1 and f <= 270:
            crop = hist_index(img(f))[int(y):int(y + h), int(x):int(x + w)]
            target_hist += np.bincount(crop.ravel(), minlength=B**3) / crop.size
    target_hist /= target_hist.sum()
    print("frame  ncc: car / best elsewhere   hist: car / best elsewhere (rank of the car)")
    for f in range(300, 345, 4):
        im = img(f)
        x, y, w, h = box(f)
        cx, cy = x + w / 2, y + h / 2
        grey = cv2.cvtColor(im, cv2.COLOR_BGR2GRAY)
        best = (-1.0, -1.0)
        for t in bank:
            s = np.sqrt(w * h * 2.25 / (t.shape[0] * t.shape[1]))
            tt = cv2.cvtColor(cv2.resize(t, None, fx=s, fy=s, interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2GRAY)
            r = cv2.matchTemplate(grey, tt, cv2.TM_CCOEFF_NORMED)
            th, tw = tt.shape
            gx, gy = int(cx - tw / 2), int(cy - th / 2)
            at_car = r[max(0, gy - 3):gy + 4, max(0, gx - 3):gx + 4].max()
            mask = np.ones_like(r, bool)
            mask[max(0, gy - 25):gy + 26, max(0, gx - 25):gx + 26] = False
            if at_car > best[0]:
                best = (float(at_car), float(r[mask].max()))
        idx = hist_index(im)
        wi, hi = int(w), int(h)
        scores = []
        for yy in range(0, im.shape[0] - hi, 6):
            for xx in range(0, im.shape[1] - wi, 6):
                p = np.bincount(idx[yy:yy + hi, xx:xx + wi].ravel(), minlength=B**3) / (wi * hi)
                scores.append((np.sqrt(p * target_hist).sum(), xx, yy))
        scores = np.array(scores)
        d = np.hypot(scores[:, 1] - x, scores[:, 2] - y)
        car, other = scores[d < 8, 0].max(), scores[d >= 25, 0]
        print(f"{f:5d}  {best[0]:.2f} / {best[1]:.2f}                 "
              f"{car:.3f} / {other.max():.3f} ({(other > car).sum() + 1})")


if __name__ == "__main__":
    main()
