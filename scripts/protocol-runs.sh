#!/usr/bin/env bash
# The selection protocol's runs of one tracker build (docs/results.md#selection-protocol):
# the dev set unperturbed and under the ten `--perturb` conditions of rule 3, one thread per
# run, JOBS runs at a time (accuracy does not depend on load; the fps in these runs mean
# nothing). Each condition's boxes and summary.json go to target/protocol/LABEL/CONDITION/;
# an existing condition folder with a summary of all sequences is kept, not run again, so an
# interrupted call resumes; a LABEL that holds runs of another binary, other arguments or
# another dataset is refused (exit 2) rather than mixed. Read the results with scripts/rule3.py.
#
# Usage: scripts/protocol-runs.sh LABEL [BEVT_EVAL_ARGS...]
#   LABEL           folder name under target/protocol (letters, digits, '.', '_', '-')
#   BEVT_EVAL_ARGS  more `bevt eval` arguments for every run, e.g. --set box_refine.interval=2
# Environment:
#   BEVT     the bevt binary (default target/release/bevt, built by cargo when missing)
#   JOBS     runs at a time (default 2)
#   DATASET  default ../shared/datasets/uav123_10fps_dev
set -euo pipefail
cd "$(dirname "$0")/.."

label=${1:-}
case "$label" in
  '' | . | .. | -* | *[!A-Za-z0-9._-]*)
    echo "protocol-runs: LABEL must be letters, digits, '.', '_' or '-' (not '.', '..' or a leading '-'), got '$label'" >&2
    exit 2 ;;
esac
shift
jobs=${JOBS:-2}
case "$jobs" in
  '' | *[!0-9]* | 0) echo "protocol-runs: JOBS must be a positive integer, got '$jobs'" >&2; exit 2 ;;
esac
dataset=${DATASET:-../shared/datasets/uav123_10fps_dev}
[ -f "$dataset/sequences.json" ] || { echo "protocol-runs: no dataset at $dataset" >&2; exit 2; }

bevt=${BEVT:-}
if [ -z "$bevt" ]; then
  cargo build --release -q -p bevt_node --bin bevt
  bevt=target/release/bevt
fi
[ -x "$bevt" ] || { echo "protocol-runs: $bevt is not an executable" >&2; exit 2; }
# A private copy: a build during the runs must not swap the binary under them.
out=target/protocol/$label
# What the runs under LABEL are of: a resumed call must be of the same binary, arguments and
# dataset, or its conditions would mix two trackers.
signature=$(printf '%s\n' "binary sha256: $(sha256sum "$bevt" | cut -d' ' -f1)" "args: $*" \
  "dataset: $(cd "$dataset" && pwd)")
if [ -f "$out/signature" ] && [ "$(cat "$out/signature")" != "$signature" ]; then
  echo "protocol-runs: $out holds runs of another binary, arguments or dataset:" >&2
  sed 's/^/  /' "$out/signature" >&2
  echo "  choose another LABEL or remove $out" >&2
  exit 2
fi
mkdir -p "$out"
printf '%s\n' "$signature" > "$out/signature"
cp "$bevt" "$out/bevt"
printf '%s\n' "binary: $bevt" "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  "start: $(date -u '+%Y-%m-%d %H:%M:%S UTC')" >> "$out/run.txt"

# name=spec; "none" runs unperturbed. The ten of rule 3, in the order of docs/results.md.
conditions=(
  none=
  shake16s1=shake=16,seed=1
  shake16s2=shake=16,seed=2
  shake8s2=shake=8,seed=2
  tiny_shake=tiny=0.5,shake=8,seed=1
  tiny=tiny=0.5
  zoom=zoom=1.5
  aspect=aspect=1.4
  light=light=2,gamma=1.5
  lookalike=lookalike=2
  blur=blur=2
)
expected=$(python3 -c 'import json, sys; print(len(json.load(open(sys.argv[1]))["sequences"]))' "$dataset/sequences.json")

complete() {
  [ -f "$1/summary.json" ] && python3 - "$1/summary.json" "$expected" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["sequences"]
sys.exit(0 if len(s) == int(sys.argv[2]) and all(q.get("status") == "ok" for q in s) else 1)
PY
}

run_one() {
  local name=${1%%=*} spec=${1#*=} dir perturb=()
  shift
  dir=$out/$name
  if complete "$dir"; then
    echo "protocol-runs: $label/$name done before, kept"
    return 0
  fi
  rm -rf "$dir"
  [ -z "$spec" ] || perturb=(--perturb "$spec")
  if "$out/bevt" eval --dataset "$dataset" --out "$dir" --threads 1 "${perturb[@]}" "$@" \
    > "$dir.log" 2>&1 && complete "$dir"; then
    echo "protocol-runs: $label/$name finished $(date -u '+%H:%M:%S')"
  else
    echo "protocol-runs: $label/$name FAILED: no complete summary (see $dir.log)" >&2
    return 1
  fi
}

failed=0
running=0
for c in "${conditions[@]}"; do
  run_one "$c" "$@" &
  running=$((running + 1))
  if [ "$running" -ge "$jobs" ]; then
    wait -n || failed=1
    running=$((running - 1))
  fi
done
while [ "$running" -gt 0 ]; do
  wait -n || failed=1
  running=$((running - 1))
done
echo "end: $(date -u '+%Y-%m-%d %H:%M:%S UTC')" >> "$out/run.txt"
[ "$failed" -eq 0 ] || { echo "protocol-runs: some runs failed" >&2; exit 1; }
echo "protocol-runs: $out complete"
