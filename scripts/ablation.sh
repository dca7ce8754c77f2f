#!/usr/bin/env bash
# Module evaluation on the dev set, in the spirit of the paper's ablation: the full
# tracker, then one module changed at a time. Accuracy is deterministic; fps is indicative
# (run one job at a time on a quiet machine). Prints a Markdown table.
#
#   scripts/ablation.sh [DATASET] [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
dataset=${1:-../shared/datasets/uav123_10fps_dev}
out=${2:-results/ablation}
cargo build --release -p bevt_node --bin bevt >/dev/null
bevt=target/release/bevt
run() {
  local name=$1; shift
  "$bevt" eval --dataset "$dataset" --out "$out/$name" --threads 1 "$@" >/dev/null || true
}
run full
run no_verification --set verification.enabled=false
run no_ebl_small_window_no_penalty --set admm.penalty=none --set window.search_area_scale=2.0
run penalty_elementwise --set admm.penalty=elementwise
run penalty_none_bacf --set admm.penalty=none
run norm_frobenius_sq --set verification.norm=frobenius_sq
run beta_10 --set admm.beta=10
run hog_without_gray --set features.grayscale=false
python3 - "$out" <<'PY'
import json, sys, os
out = sys.argv[1]
names = ["full", "no_verification", "no_ebl_small_window_no_penalty", "penalty_elementwise",
         "penalty_none_bacf", "norm_frobenius_sq", "beta_10", "hog_without_gray"]
print("| variant | P@20 | AUC | SR@0.5 | frames skipped | fps (mean / pooled) |")
print("|---|---|---|---|---|---|")
for n in names:
    p = os.path.join(out, n, "summary.json")
    if not os.path.exists(p):
        print(f"| {n} | missing | | | | |"); continue
    s = json.load(open(p)); o = s["overall"]
    skipped = sum(q["skipped"] for q in s["sequences"])
    print(f"| {n} | {o['precision_20']:.3f} | {o['auc']:.3f} | {o['success_50']:.3f} | {skipped} | {o.get('fps_mean',0):.0f} / {o.get('fps_pooled',0):.0f} |")
PY
