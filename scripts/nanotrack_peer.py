#!/usr/bin/env python3
"""OpenCV TrackerNano (NanoTrack v2) on a UAV123-style dataset, for a back-to-back speed
comparison with `bevt eval` on the same machine.

One thread (cv2.setNumThreads(1)); per frame cv2.imread is timed separately and excluded;
tracking time = init + update, as `bevt eval` counts it. Writes <out>/<sequence>.txt (one
x,y,w,h row per frame, the boxes as OpenCV returns them; the previous box is held when
update reports failure) and <out>/timing.json, and prints per-sequence and pooled fps
(total frames / total tracking time). Score the boxes with
`bevt eval ... --compare OpenCV-Nano-v2-here=<out>`.

scripts/speed-rounds.sh runs it in turn with `bevt eval` (its own venv under target/). By hand
(a venv of its own: opencv is a peer, not a test dependency, and the project's .venv belongs to
scripts/python-env.sh):
    python3 -m venv target/venv-peers
    target/venv-peers/bin/python -m pip install -r scripts/requirements-peers.txt
    target/venv-peers/bin/python scripts/nanotrack_peer.py [--sequences a,b] [DATASET] [OUT] [MODELS]
`--sequences` runs only the named sequences of the manifest (all by default).
"""
import json
import math
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def read_boxes(path):
    boxes = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            vals = [float(v) for v in line.replace(",", " ").split()]
            boxes.append(vals)
    return boxes


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    root = os.path.dirname(here)
    args = sys.argv[1:]
    only = None
    if "--sequences" in args:
        i = args.index("--sequences")
        if i + 1 >= len(args):
            raise SystemExit("--sequences needs a comma-separated list of sequence names")
        only = [n for n in args[i + 1].split(",") if n]
        del args[i:i + 2]
    sys.argv[1:] = args
    dataset = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "../shared/datasets/uav123_10fps_dev")
    out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(root, "results/nanotrack_peer")
    models = sys.argv[3] if len(sys.argv) > 3 else os.path.join(root, "../shared/models/nanotrack")
    manifest = json.load(open(os.path.join(dataset, "sequences.json")))
    if only is not None:
        known = {seq["name"] for seq in manifest["sequences"]}
        unknown = [n for n in only if n not in known]
        if unknown or not only:
            raise SystemExit(f"--sequences: not in the manifest: {unknown or '(empty list)'}")
        manifest["sequences"] = [seq for seq in manifest["sequences"] if seq["name"] in only]
    # Arguments checked before opencv is loaded or anything is written.
    import cv2

    os.makedirs(out, exist_ok=True)
    cv2.setNumThreads(1)
    p = cv2.TrackerNano_Params()
    p.backbone = os.path.join(models, "nanotrackv2_backbone_sim.onnx")
    p.neckhead = os.path.join(models, "nanotrackv2_head_sim.onnx")
    timing = {"tracker": "OpenCV-Nano-v2", "cv2": cv2.__version__, "threads": cv2.getNumThreads(),
              "loadavg_start": list(os.getloadavg()), "sequences": {}}
    total_frames, total_s = 0, 0.0
    for seq in manifest["sequences"]:
        name = seq["name"]
        gt = read_boxes(os.path.join(dataset, seq["anno"]))
        frames = range(seq["start_frame"], seq["end_frame"] + 1)
        nz, ext = seq.get("nz", 6), seq.get("ext", "jpg")
        tracker = cv2.TrackerNano_create(p)
        boxes, track_s = [], 0.0
        box = tuple(int(round(v)) for v in gt[0])
        for i, fno in enumerate(frames):
            img = cv2.imread(os.path.join(dataset, seq["img_dir"], f"{fno:0{nz}d}.{ext}"))
            if img is None:
                raise SystemExit(f"{name}: cannot read frame {fno}")
            t0 = time.perf_counter()
            if i == 0:
                tracker.init(img, box)
            else:
                ok, b = tracker.update(img)
                if ok and b[2] > 0 and b[3] > 0:
                    box = tuple(b)
            track_s += time.perf_counter() - t0
            boxes.append(box)
        with open(os.path.join(out, f"{name}.txt"), "w") as f:
            for b in boxes:
                f.write(",".join(str(v) for v in b) + "\n")
        n = len(boxes)
        total_frames += n
        total_s += track_s
        fps = n / track_s if track_s > 0 else math.inf
        timing["sequences"][name] = {"frames": n, "track_s": track_s, "fps": fps}
        print(f"{name:>12}: {n} frames, {fps:.1f} fps", flush=True)
    pooled = total_frames / total_s if total_s > 0 else math.inf
    timing.update({"frames": total_frames, "track_s": total_s, "fps_pooled": pooled,
                   "loadavg_end": list(os.getloadavg())})
    json.dump(timing, open(os.path.join(out, "timing.json"), "w"), indent=1)
    print(f"OpenCV-Nano-v2: {total_frames} frames, pooled {pooled:.1f} fps (one thread, tracking only)")


if __name__ == "__main__":
    main()
