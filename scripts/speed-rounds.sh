#!/usr/bin/env bash
# Back-to-back speed rounds on the dev set, one thread each: the default, the default without
# the drift rules, and OpenCV TrackerNano (scripts/nanotrack_peer.py, NanoTrack v2), taking
# turns sequence by sequence, ROUNDS times. Prints every round's pooled fps (frames / tracking
# time, decoding excluded for all three and done on the tracking thread between the timed
# calls, as the peer's harness does: `bevt eval --decode inline`), the means, the default
# against TrackerNano (issue 19 asks >= 1.0x) and what the drift rules cost (issue 20 allows
# 10 %). These VMs' speed changes by tens of percent within seconds, hence the turns by
# sequence, and only figures of one run are compared with each other; docs/benchmarks.md
# quotes this script's.
#
# Usage: scripts/speed-rounds.sh [ROUNDS] [DATASET]
#        scripts/speed-rounds.sh --summarise DIR   (the summary of an earlier run's DIR again)
#   ROUNDS   rounds of the three runs (default 5)
#   DATASET  default ../shared/datasets/uav123_10fps_dev
# Environment:
#   BEVT       the bevt binary (default target/release/bevt, built by cargo when missing)
#   PEER_VENV  venv with scripts/requirements-peers.txt (default target/venv-peers, created
#              when it cannot import cv2; the project's .venv belongs to scripts/python-env.sh)
#   WITHOUT    sequences left out of the second comparison, split at commas (default wakeboard4:
#              issue 19 sets its targets with and without it, since it flips on small changes;
#              empty for none)
#   DECODE     where our runs decode (default inline; `ahead`, a thread beside the tracker, is
#              how runs before c2f3101 (2026-12-06) were timed: it costs the tracker about 2 % here)
#   BEVT_ARGS  more `bevt eval` arguments for both of our runs, split at spaces (e.g.
#              "--set redetection.verifier_filter_hint=true": an option with and without the rules)
# Boxes and logs of every run stay in a new directory under target/ (printed); nothing else
# is written.
set -euo pipefail
cd "$(dirname "$0")/.."
# WITHOUT as given must name sequences that ran; its default only where wakeboard4 did.
without=${WITHOUT-wakeboard4}
strict=${WITHOUT+1}
# The median of a[1..k] (an insertion sort), for both summaries' awk programs.
median='
  function median(a, k,    i, j, t) {
    for (i = 2; i <= k; i++) for (j = i; j > 1 && a[j - 1] > a[j]; j--) { t = a[j]; a[j] = a[j - 1]; a[j - 1] = t }
    return k % 2 ? a[(k + 1) / 2] : (a[k / 2] + a[k / 2 + 1]) / 2
  }'
# The summary of the rounds in "$out" (fps.txt: a round's three pooled fps a line;
# round_R.txt: "tracker frames seconds sequence" a run), leaving out the $without sequences in its
# last line. Means over the rounds, and the per-round ratios (each round's runs ran minutes apart
# at most): their median and range show how much the VM's drift moves the ratio of the means.
summarise() {
  awk "$median"'
    { d += $1; o += $2; n += $3; k++; rn[k] = $1 / $3; ro[k] = $2 / $3; rc[k] = 100 * (1 - $1 / $2)
      lo1 = (k == 1 || rn[k] < lo1) ? rn[k] : lo1; hi1 = (k == 1 || rn[k] > hi1) ? rn[k] : hi1
      lo3 = (k == 1 || rc[k] < lo3) ? rc[k] : lo3; hi3 = (k == 1 || rc[k] > hi3) ? rc[k] : hi3 }
    END {
      d /= k; o /= k; n /= k
      printf "mean   %10.1f %10.1f %13.1f\n", d, o, n
      printf "default against TrackerNano: %.2fx of the means; per round median %.2fx, %.2f-%.2fx (issue 19: >= 1.0x)\n", d / n, median(rn, k), lo1, hi1
      printf "without the drift rules against TrackerNano: %.2fx of the means; per round median %.2fx\n", o / n, median(ro, k)
      printf "the drift rules cost: %.1f %% of the means; per round median %.1f %%, %.1f to %.1f %% (issue 20: <= 10 %%)\n", 100 * (1 - d / o), median(rc, k), lo3, hi3
    }' "$out/fps.txt"
  # Per sequence over all rounds (frames / seconds of each tracker), and the default against
  # TrackerNano without the WITHOUT sequences, computed as above from each round's own sums.
  [ -z "$without" ] || awk -v without="$without" -v strict="${strict:-0}" "$median"'
    BEGIN { n = split(without, w, ","); for (i = 1; i <= n; i++) skip[w[i]] = 1 }
    FNR == 1 { k++ }
    { f[$1, $4] += $2; t[$1, $4] += $3; seen[$4] = 1
      if (!($4 in skip)) { rf[k, $1] += $2; rt[k, $1] += $3 } }
    END {
      for (x in skip) if (!(x in seen)) {
        if (!strict) exit
        printf "speed-rounds: WITHOUT names %s, which no round ran\n", x > "/dev/stderr"; bad = 1
      }
      if (!bad && !rt[1, "default"]) { print "speed-rounds: WITHOUT leaves no sequence" > "/dev/stderr"; bad = 1 }
      if (bad) exit 2
      printf "%-14s %10s %13s %7s\n", "sequence", "default", "TrackerNano", "ratio"
      for (s in seen) printf "%-14s %10.1f %13.1f %6.2fx\n", s, f["default", s] / t["default", s], f["nano", s] / t["nano", s], (f["default", s] / t["default", s]) / (f["nano", s] / t["nano", s]) | "sort"
      close("sort")
      for (i = 1; i <= k; i++) { d = rf[i, "default"] / rt[i, "default"]; m = rf[i, "nano"] / rt[i, "nano"]; sd += d; sn += m; r[i] = d / m
        lo = (i == 1 || r[i] < lo) ? r[i] : lo; hi = (i == 1 || r[i] > hi) ? r[i] : hi }
      printf "default against TrackerNano without %s: %.2fx of the means (%.1f against %.1f fps); per round median %.2fx, %.2f-%.2fx\n", without, sd / sn, sd / k, sn / k, median(r, k), lo, hi
    }' "$out"/round_*.txt
}

if [ "${1:-}" = --summarise ]; then
  out=${2:-}
  if [ -z "$out" ] || [ ! -s "$out/fps.txt" ] || ! ls "$out"/round_*.txt >/dev/null 2>&1; then
    echo "speed-rounds: --summarise needs the folder of an earlier run (its fps.txt and round_*.txt), got '$out'" >&2
    exit 2
  fi
  summarise
  exit
fi

rounds=${1:-5}
dataset=${2:-../shared/datasets/uav123_10fps_dev}
case "$rounds" in
  '' | *[!0-9]* | 0) echo "speed-rounds: ROUNDS must be a positive integer, got '$rounds'" >&2; exit 2 ;;
esac
if [ "$rounds" -gt 100 ]; then
  echo "speed-rounds: at most 100 rounds (about 1 minute each), got $rounds" >&2
  exit 2
fi
decode=${DECODE:-inline}
case "$decode" in
  inline | ahead) ;;
  *) echo "speed-rounds: DECODE must be 'inline' or 'ahead', got '$decode'" >&2; exit 2 ;;
esac
if [ ! -f "$dataset/sequences.json" ]; then
  echo "speed-rounds: no dataset at $dataset (sequences.json missing)" >&2
  exit 2
fi
if [ -n "$without" ]; then
  python3 - "$dataset/sequences.json" "$without" "${strict:-0}" <<'PY' || exit 2
import json, sys
names = {s["name"] for s in json.load(open(sys.argv[1]))["sequences"]}
left = set(sys.argv[2].split(","))
unknown = sorted(left - names)
if unknown and sys.argv[3] == "1":
    sys.exit(f"speed-rounds: WITHOUT names sequences not in the dataset: {unknown}")
if not unknown and not names - left:
    sys.exit("speed-rounds: WITHOUT leaves no sequence")
PY
fi

bevt=${BEVT:-}
if [ -z "$bevt" ]; then
  cargo build --release -q -p bevt_node --bin bevt
  bevt=target/release/bevt
fi
[ -x "$bevt" ] || { echo "speed-rounds: $bevt is not an executable" >&2; exit 2; }

venv=${PEER_VENV:-target/venv-peers}
if ! "$venv/bin/python" -c 'import cv2' 2>/dev/null; then
  echo "speed-rounds: installing the peer's venv in $venv (scripts/requirements-peers.txt)" >&2
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install -q -r scripts/requirements-peers.txt
fi

mkdir -p target
out=$(mktemp -d target/speed-rounds.XXXXXX)
rules_off=(--set track_state.drift_check_frames=0 --set track_state.verify_low_confidence=false)
read -r -a extra <<<"${BEVT_ARGS:-}"

echo "speed-rounds: $rounds rounds on $dataset, results in $out"
echo "machine: $(nproc) cores, $(lscpu 2>/dev/null | sed -n 's/^Model name: *//p' | head -n 1)"
echo "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)$(git diff --quiet 2>/dev/null || echo ' (with uncommitted changes)'), binary $bevt"
echo "start: $(date -u '+%Y-%m-%d %H:%M:%S UTC'), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "our runs decode: $decode"
[ -z "${BEVT_ARGS:-}" ] || echo "our runs with: $BEVT_ARGS"

# The tracking seconds and frames of one run: bevt's summary.json (frames / fps per sequence),
# the peer's timing.json (track_s).
seconds() {
  "$venv/bin/python" - "$1" "$2" <<'PY'
import json, sys
kind, d = sys.argv[1], sys.argv[2]
if kind == "bevt":
    s = json.load(open(f"{d}/summary.json"))["sequences"]
    bad = [q["name"] for q in s if q.get("status") != "ok" or not q.get("fps")]
    if bad:
        sys.exit(f"speed-rounds: {d}: sequence(s) {bad} did not track (see its log)")
    print(sum(q["frames"] for q in s), sum(q["frames"] / q["fps"] for q in s))
else:
    s = json.load(open(f"{d}/timing.json"))["sequences"].values()
    print(sum(q["frames"] for q in s), sum(q["track_s"] for q in s))
PY
}
sequences=$("$venv/bin/python" -c 'import json, sys; print(" ".join(s["name"] for s in json.load(open(sys.argv[1]))["sequences"]))' "$dataset/sequences.json")

# One run of `which` on sequence `seq`, appending "which frames seconds" to the round's file.
run() {
  local which=$1 seq=$2 dir="$out/r${r}_$1_$2"
  case "$which" in
    default) "$bevt" eval --dataset "$dataset" --out "$dir" --threads 1 --decode "$decode" --sequences "$seq" \
      ${extra[@]+"${extra[@]}"} >"$dir.log" 2>&1 ;;
    rules_off) "$bevt" eval --dataset "$dataset" --out "$dir" --threads 1 --decode "$decode" --sequences "$seq" \
      ${extra[@]+"${extra[@]}"} "${rules_off[@]}" >"$dir.log" 2>&1 ;;
    nano) "$venv/bin/python" scripts/nanotrack_peer.py --sequences "$seq" "$dataset" "$dir" >"$dir.log" 2>&1 ;;
  esac || { echo "speed-rounds: $which on $seq failed, see $dir.log" >&2; exit 1; }
  local kind=bevt
  [ "$which" = nano ] && kind=peer
  echo "$which $(seconds "$kind" "$dir") $seq" >>"$out/round_$r.txt"
}

# The three trackers take turns sequence by sequence (in a rotating order), so a change of the
# VM's speed falls on all three alike unless it comes within one sequence's few seconds; a round's pooled fps is
# its frames over its tracking seconds, over every sequence.
printf '%-6s %10s %10s %13s\n' round default rules_off TrackerNano
for r in $(seq 1 "$rounds"); do
  i=0
  for seq in $sequences; do
    case $((i % 3)) in
      0) order="default rules_off nano" ;;
      1) order="rules_off nano default" ;;
      *) order="nano default rules_off" ;;
    esac
    for which in $order; do run "$which" "$seq"; done
    i=$((i + 1))
  done
  line=$(awk '{ f[$1] += $2; t[$1] += $3 }
    END { printf "%.1f %.1f %.1f", f["default"] / t["default"], f["rules_off"] / t["rules_off"], f["nano"] / t["nano"] }' \
    "$out/round_$r.txt")
  read -r d o n <<<"$line"
  printf '%-6s %10s %10s %13s\n' "$r" "$d" "$o" "$n"
  echo "$d $o $n" >>"$out/fps.txt"
done
echo "end: $(date -u '+%Y-%m-%d %H:%M:%S UTC'), load $(cut -d' ' -f1-3 /proc/loadavg)"
summarise
