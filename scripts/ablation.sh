#!/usr/bin/env bash
# Module evaluation on the dev set: the authors' reference (config/bevt_reference.yaml), each
# fast-mode addition alone on top of it, all of them together (the default config/bevt.yaml, rows
# "default*"), then the default with one module changed back at a time, temporal regularisation
# (admm.temporal), scale-sample padding and the scale filter's 10 fps settings on top of it; plus the reference's own modules
# (verification, enhanced background learning, beta, grayscale). Accuracy is deterministic;
# fps is indicative (run on a quiet machine). Prints a Markdown table with the mean over the
# 7 sequences and over the 6 without the bimodal wakeboard4.
#
#   scripts/ablation.sh [DATASET] [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
dataset=${1:-../shared/datasets/uav123_10fps_dev}
out=${2:-results/ablation}
cargo build --release -p bevt_node --bin bevt >/dev/null
bevt=target/release/bevt
ref=(--config config/bevt_reference.yaml)
fast=(--config config/bevt.yaml)
run() {
  local name=$1; shift
  "$bevt" eval --dataset "$dataset" --out "$out/$name" --threads 1 "$@" >/dev/null || true
}
run reference "${ref[@]}"
run ref+colornames "${ref[@]}" --set features.colornames=true
run ref+scale_filter "${ref[@]}" --set detection.scale_estimator=filter
run ref+shifted_sample "${ref[@]}" --set learning.training_sample=shifted
run ref+elementwise "${ref[@]}" --set admm.penalty=elementwise
run ref+penalty_none "${ref[@]}" --set admm.penalty=none
run default "${fast[@]}"
run default-colornames "${fast[@]}" --set features.colornames=false
run default-scale_filter "${fast[@]}" --set detection.scale_estimator=search
run default-shifted_sample "${fast[@]}" --set learning.training_sample=fresh
run default_penalty_matrix "${fast[@]}" --set admm.penalty=matrix
run default_penalty_none "${fast[@]}" --set admm.penalty=none
run default_elementwise_kappa3 "${fast[@]}" --set admm.spatial_weight=3
run default_elementwise_kappa30 "${fast[@]}" --set admm.spatial_weight=30
run default_temporal_0.5 "${fast[@]}" --set admm.temporal=0.5
run default_temporal_1 "${fast[@]}" --set admm.temporal=1
run default_temporal_2 "${fast[@]}" --set admm.temporal=2
run default_temporal_5 "${fast[@]}" --set admm.temporal=5
run default_scale_padding_1.5 "${fast[@]}" --set scale_filter.padding=1.5
run default_scale_padding_2 "${fast[@]}" --set scale_filter.padding=2
# The scale filter at 10 fps (README "the scale filter at 10 fps"): fDSST's values back, then
# each change alone.
fdsst=(--set scale_filter.step=1.02 --set scale_filter.learning_rate=0.025 --set scale_filter.colornames=false)
run default_scale_fdsst "${fast[@]}" "${fdsst[@]}"
run default_scale_fdsst+colornames "${fast[@]}" "${fdsst[@]}" --set scale_filter.colornames=true
run default_scale_fdsst+lr0.075 "${fast[@]}" "${fdsst[@]}" --set scale_filter.learning_rate=0.075
run default_scale_fdsst+step1.03 "${fast[@]}" "${fdsst[@]}" --set scale_filter.step=1.03
run default_scale_no_colornames "${fast[@]}" --set scale_filter.colornames=false
run default_scale_lr0.025 "${fast[@]}" --set scale_filter.learning_rate=0.025
run default_scale_lr0.05 "${fast[@]}" --set scale_filter.learning_rate=0.05
run default_scale_step1.025 "${fast[@]}" --set scale_filter.step=1.025
run default_scale_step1.035 "${fast[@]}" --set scale_filter.step=1.035
run ref_no_verification "${ref[@]}" --set verification.enabled=false
run ref_no_ebl_small_window_no_penalty "${ref[@]}" --set admm.penalty=none --set window.search_area_scale=2.0
run ref_beta_10 "${ref[@]}" --set admm.beta=10
run ref_without_gray "${ref[@]}" --set features.grayscale=false
python3 - "$out" <<'PY'
import json, sys, os
out = sys.argv[1]
names = ["reference", "ref+colornames", "ref+scale_filter", "ref+shifted_sample", "ref+elementwise",
         "ref+penalty_none", "default", "default-colornames", "default-scale_filter",
         "default-shifted_sample", "default_penalty_matrix", "default_penalty_none",
         "default_elementwise_kappa3", "default_elementwise_kappa30", "default_temporal_0.5",
         "default_temporal_1", "default_temporal_2", "default_temporal_5",
         "default_scale_padding_1.5", "default_scale_padding_2", "default_scale_fdsst",
         "default_scale_fdsst+colornames", "default_scale_fdsst+lr0.075",
         "default_scale_fdsst+step1.03", "default_scale_no_colornames", "default_scale_lr0.025",
         "default_scale_lr0.05", "default_scale_step1.025", "default_scale_step1.035",
         "ref_no_verification",
         "ref_no_ebl_small_window_no_penalty", "ref_beta_10", "ref_without_gray"]
print("| variant | P@20 | AUC | P@20 / AUC without wakeboard4 | truck4_1 | wakeboard10 | wakeboard7 | fps pooled |")
print("|---|---|---|---|---|---|---|---|")
for n in names:
    p = os.path.join(out, n, "summary.json")
    if not os.path.exists(p):
        print(f"| {n} | missing | | | | | | |"); continue
    s = json.load(open(p)); o = s["overall"]
    seqs = {q["name"]: q for q in s["sequences"]}
    rest = [q for k, q in seqs.items() if k != "wakeboard4"]
    p6 = sum(q["precision_20"] for q in rest) / len(rest)
    a6 = sum(q["auc"] for q in rest) / len(rest)
    cell = lambda k: f"{seqs[k]['auc']:.2f} / {seqs[k]['precision_20']:.2f}" if k in seqs else ""
    print(f"| {n} | {o['precision_20']:.3f} | {o['auc']:.3f} | {p6:.3f} / {a6:.3f} | {cell('truck4_1')} | "
          f"{cell('wakeboard10')} | {cell('wakeboard7')} | {o.get('fps_pooled', 0):.0f} |")
PY
