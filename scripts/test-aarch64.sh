#!/usr/bin/env bash
# The aarch64 build tested under user-mode emulation (qemu-aarch64), against the x86_64 build:
#   1. bevt_core's unit tests, cross-built for aarch64-unknown-linux-gnu, run under qemu;
#   2. `bevt_node --help` and `bevt --help` of the cross-built programs;
#   3. `bevt eval` on one dev sequence (default wakeboard7) by the aarch64 `bevt` under qemu
#      and by the native x86_64 `bevt`; the track states must be equal and every box must
#      agree within TOLERANCE_PX pixels (each of x, y, w, h).
#   With AARCH64_PROGRAMS=0 (what .ci/run uses) 2. is left out and 3. is run by bevt_core's
#   example `track_sequence` (the default tracker on the sequence's JPEG frames, the same
#   output formats) instead of `bevt eval`: only bevt_core and its 70-odd crates are
#   cross-built, not the node's 230 (RustDDS, tokio, image, ...): 122 against 340 CPU-s on
#   2026-12-02 (docs/testing.md#ci). The tracker's arithmetic on aarch64, which is what
#   differs between the architectures, is tested the same way; the programs' aarch64 build
#   is then scripts/build-aarch64.sh's and scripts/build-deb.sh's, not CI's. They are not bit-identical: floating-point results differ by
#      ulps between the architectures (glibc's libm, rustfft's NEON and x86 paths), and the
#      tracker feeds each frame's box into the next. wakeboard7 on 2026-11-25: boxes equal
#      for frames 1-5, largest difference 1.22 px (docs/deploy.md#aarch64-jetson). A target
#      lost on one architecture only would differ by tens of pixels.
#
# Usage: scripts/test-aarch64.sh [--build | --check] [SEQUENCE]
#   --build   only install the toolchain and cross-build (1.'s test harness, 2.'s programs)
#   --check   only run 1.-3. on what an earlier --build built (same AARCH64_TARGET_DIR)
#   neither   both, one after the other
# .ci/run starts `--build` in the background at low priority right after its installs, so
# the cross build uses the cores the x86_64 steps leave idle, and runs `--check` at the end.
# In --check the unit tests under qemu run beside the two evals: the emulated runs wait on
# futexes and memory more than they compute (docs/testing.md#ci).
# Environment:
#   AARCH64_TARGET_DIR  cargo target dir of the cross build (default: cargo's own). .ci/run
#                    gives it its own, so that the background cross build never waits for
#                    the lock of the x86_64 build directory; the native `bevt` of 3. always
#                    comes from cargo's own target dir (CARGO_TARGET_DIR or ./target)
#   BEVT_DATASET     dataset root (default ../shared/datasets/uav123_10fps_dev)
#   TOLERANCE_PX     largest allowed |aarch64 - x86_64| of a box coordinate (default below)
#   AARCH64_FEATURES cargo features of bevt_node for the cross build (default `jazzy`: no DDS
#                    Security, so no arm64 OpenSSL to install; the tracker is the same code)
#   QEMU_TIMEOUT_S   time limit of each emulated run (the unit tests, the eval; default 900)
#   AARCH64_PROGRAMS 1 (default): cross-build and check the programs as above; 0: bevt_core
#                    only (its unit tests and the example); the same value for --build and
#                    --check
#
# Installs what is missing (rustup target, gcc-aarch64-linux-gnu, qemu-user). Nothing is
# skipped: a missing tool, dataset or sequence is an error (exit 1), as is any mismatch.
#
# Cost (docs/testing.md#ci): the test build and the programs are one feature resolution
# (`-p bevt_core -p bevt_node` in both cargo commands), so every dependency is compiled once
# for aarch64; a cargo command with `-p bevt_core` alone resolves shared dependencies'
# features differently from one with `-p bevt_node` and compiled the network engine's tree
# (tract, then) twice. Dev profile (the profile the tests use, with its per-package opt-levels), so under
# CI the native `bevt` is the one `cargo test --workspace` already built; no incremental
# state for a one-off build.
set -euo pipefail
cd "$(dirname "$0")/.."

triple=aarch64-unknown-linux-gnu
mode=all
case "${1:-}" in
  --build) mode=build; shift ;;
  --check) mode=check; shift ;;
  -*) echo "test-aarch64: unknown option '$1' (--build or --check)" >&2; exit 2 ;;
esac
sequence=${1:-wakeboard7}
dataset=${BEVT_DATASET:-../shared/datasets/uav123_10fps_dev}
tolerance=${TOLERANCE_PX:-3}
features=${AARCH64_FEATURES:-jazzy}
QEMU_TIMEOUT_S=${QEMU_TIMEOUT_S:-900}
programs=${AARCH64_PROGRAMS:-1}
case "$programs" in
  0 | 1) ;;
  *) echo "test-aarch64: AARCH64_PROGRAMS must be 0 or 1, not '$programs'" >&2; exit 2 ;;
esac

fail() { echo "test-aarch64: FAILED: $*" >&2; exit 1; }
step() { printf 'test-aarch64: %s (%ss)\n' "$1" "$SECONDS" >&2; }

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
apt_updated=
apt_install() {
  # Wait for another apt-get (CI's Fast DDS step may run one at the same time).
  [ -n "$apt_updated" ] || { as_root apt-get -o DPkg::Lock::Timeout=600 update -q >/dev/null; apt_updated=1; }
  as_root env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -q "$@" >/dev/null
}

step "toolchain"
if [ "$mode" = check ]; then
  # Installed by the --build that came before.
  rustup target list --installed | grep -qx "$triple" || fail "no Rust target $triple (run --build first)"
else
  if ! rustup target list --installed | grep -qx "$triple"; then
    rustup target add "$triple"
  fi
  command -v aarch64-linux-gnu-gcc >/dev/null || apt_install gcc-aarch64-linux-gnu
  command -v qemu-aarch64 >/dev/null || apt_install qemu-user
fi
for tool in aarch64-linux-gnu-gcc qemu-aarch64; do
  command -v "$tool" >/dev/null || fail "$tool is missing after installing it"
done
[ -d "$dataset" ] || fail "no dataset at $dataset (set BEVT_DATASET)"
[ -d "$dataset/data_seq/$sequence" ] || fail "no sequence $sequence in $dataset/data_seq"

# shellcheck source=build-aarch64.sh
. scripts/build-aarch64.sh env
# The caller's setting, for the native build below (.ci/run exports 0; a developer's shell
# usually leaves it unset).
native_incremental=(env -u CARGO_INCREMENTAL)
[ -z "${CARGO_INCREMENTAL+set}" ] || native_incremental=(env CARGO_INCREMENTAL="$CARGO_INCREMENTAL")
export CARGO_INCREMENTAL=0
target_dir=${CARGO_TARGET_DIR:-$PWD/target}
cross_dir=${AARCH64_TARGET_DIR:-$target_dir}
arm_bin="$cross_dir/$triple/debug"
# Where --build leaves the path of bevt_core's test executable for --check.
core_tests_file="$cross_dir/$triple/bevt-core-unit-tests.path"
read -ra qemu <<<"$BEVT_QEMU_AARCH64"
work=$(mktemp -d)
unit_pid=
trap '[ -z "$unit_pid" ] || kill "$unit_pid" 2>/dev/null; rm -rf "$work"' EXIT

if [ "$mode" != check ]; then
  # One package selection and one feature set for both cargo commands below. bevt_node's
  # features are named per package (a multi-package command cannot take bare ones), and
  # bevt_core keeps its default features.
  node_features=$(tr ',' '\n' <<<"$features" | sed '/^ *$/d; s#^ *#bevt_node/#' | paste -sd, -)
  [ -n "$node_features" ] || fail "AARCH64_FEATURES is empty (name a ROS distro feature: jazzy or humble)"
  selection=(--locked --target "$triple" -p bevt_core -p bevt_node --no-default-features
    --features "bevt_core/default,$node_features")
  if [ "$programs" = 0 ]; then
    # bevt_core alone, with its default features (its example for 3. is built below).
    selection=(--locked --target "$triple" -p bevt_core)
  fi
  # The cross build's own settings, for its two cargo commands only (the native build below
  # must keep the test command's profile, or it would all be compiled again): its own target
  # dir; no line tables for our crates (the dependencies have none in dev already), which
  # the tests and the eval under qemu do not read; and opt-level 0 for every package
  # `Cargo.toml` does not name (the dev profile's own default since 2026-12-03; kept here so
  # that the cross build stays so if the profile changes): what runs per frame under qemu
  # keeps its own level (bevt_core and bevt_msgs at 3, the FFT, matrix and image decoding
  # crates at 3, and the generic code bevt_core instantiates), the rest is glue run once.
  # The cross build is CI's longest path and CI is CPU-bound.
  cross_env=(env CARGO_TARGET_DIR="$cross_dir" CARGO_PROFILE_DEV_DEBUG=false
    CARGO_PROFILE_DEV_OPT_LEVEL=0)

  if [ "$programs" = 1 ]; then
    step "build bevt_core's unit tests for $triple (bevt_node features: $features)"
  else
    step "build bevt_core's unit tests for $triple (bevt_core alone)"
  fi
  rm -f "$core_tests_file"
  # `--lib` of both packages also builds bevt_node's unit-test harness, which is not run here
  # (its tests run natively in `cargo test --workspace`): naming bevt_node is what keeps this
  # command's feature resolution equal to the program build's below, and no cargo option
  # leaves out one package's harness. `Cargo.toml` compiles bevt_node at opt-level 0 in dev
  # and test builds (12 CPU-s for this harness against 41 at 1, 2026-11-27). Running it under
  # qemu instead would cost more than compiling it (43 CPU-s, 2026-11-27), and one of its
  # tests fails there (tool::pipe::tests::a_closed_stdout_ends_the_program_quietly).
  "${cross_env[@]}" cargo test --no-run "${selection[@]}" --lib \
    --message-format=json-render-diagnostics >"$work/test-build.json" ||
    fail "cross build of the unit tests"
  # The executable of target NAME from cargo's messages, the test harness or not (KIND).
  artifact() {
    python3 - "$work/test-build.json" "$1" "$2" <<'EOF'
import json
import sys

name, test = sys.argv[2], sys.argv[3] == "test"
for line in open(sys.argv[1]):
    try:
        msg = json.loads(line)
    except ValueError:
        continue
    if (msg.get("reason") == "compiler-artifact" and msg.get("executable")
            and msg["target"]["name"] == name and msg["profile"]["test"] == test):
        print(msg["executable"])
EOF
  }
  core_tests=$(artifact bevt_core test)
  [ -n "$core_tests" ] && [ -x "$core_tests" ] || fail "no bevt_core test executable in cargo's output"

  if [ "$programs" = 1 ]; then
    step "build bevt_node and bevt for $triple"
    "${cross_env[@]}" cargo build "${selection[@]}" --bin bevt_node --bin bevt ||
      fail "cross build of the programs"
  else
    # A program, not `cargo test --example` (which would build it as a test harness).
    step "build bevt_core's example track_sequence for $triple"
    "${cross_env[@]}" cargo build "${selection[@]}" --example track_sequence ||
      fail "cross build of the example"
  fi
  # Written last: a --check finds it only after a complete build.
  printf '%s\n' "$core_tests" >"$core_tests_file"
  if [ "$mode" = build ]; then
    step "built (run --check to test)"
    exit 0
  fi
fi

core_tests=$(cat "$core_tests_file" 2>/dev/null) || fail "nothing built in $cross_dir (run --build first)"
[ -x "$core_tests" ] || fail "$core_tests (from $core_tests_file) is missing"
file -b "$core_tests" | grep -q 'ARM aarch64' || fail "$core_tests is not an aarch64 program"
if [ "$programs" = 1 ]; then
  arm_progs=("$arm_bin/bevt_node" "$arm_bin/bevt")
else
  arm_progs=("$arm_bin/examples/track_sequence")
fi
for prog in "${arm_progs[@]}"; do
  file -b "$prog" | grep -q 'ARM aarch64' ||
    fail "$prog is not an aarch64 program (built with another AARCH64_PROGRAMS than $programs?)"
done

# Left out under emulation, by name (listed in the output): the tracker tests that run the
# NanoTrack networks frame after frame (and the head test that plans and runs it three
# times). When tract ran the networks (until 2026-11-27) the dev profile built it at
# opt-level 0 and qemu emulated that instruction by instruction: the first seven took 53-623 s
# each, about 20 minutes together (2026-11-25), the three added since (box_refine, the head
# split) each over 5 minutes (2026-11-26), against about 40 s for the other 137
# (docs/testing.md#ci); the drift anchor's test runs the verifier on 65 frames, as the drift
# tests do. bevt_core::nn runs them at bevt_core's opt-level 3 since; measured again under qemu
# on 2026-11-27 (the AMD host, 8021a8b): the drift test 115 s, a box_refine test 79 s, so these
# stay out; the head test (planning and running the head three times) took 4 s and runs again. They run natively in `cargo test --workspace`;
# on aarch64 the network code is exercised by the eval below, whose default configuration
# runs the NanoTrack drift check every 15 confident frames and whose boxes and states must
# match. Also left out: the lost-state search tests of `redetection.verifier_filter_hint`
# and `redetection.verifier_proposals` (no network, a mock verifier, but about 50 lost
# frames of 960×540 with 8 filter windows each: 5 s natively), the test of `redetection.filter_search` (a mock verifier, two runs of
# 90 frames of 960×540, up to 48 of them lost: 5 s natively), and the camera motion tests (no network either, but six runs of 50 and
# three of 60 shaken 480×320 frames with lost stretches: the first about 110 s of the qemu step beside the evals,
# 2026-11-28, against a thin 20-minute CI margin); the stage's own unit tests (`motion::tests`:
# the phase correlation and both motion models) still run here.
skipped=(
  tracker::tests::camera_motion_compensation_keeps_a_small_target_through_camera_jerks
  tracker::tests::the_lost_search_moves_with_the_scene_under_camera_motion
  tracker::tests::a_confirmed_drift_makes_the_track_lost_with_its_reason
  tracker::tests::box_refine_steps_aside_under_min_side_and_does_not_hurt_a_small_target
  tracker::tests::box_refine_does_not_jump_to_a_look_alike_beside_the_target
  tracker::tests::box_refine_follows_an_aspect_change_the_filter_cannot
  tracker::tests::box_refine_keeps_up_with_a_fast_size_change
  tracker::tests::box_refine_leaves_the_filter_track_alone_and_changes_only_the_box
  tracker::tests::box_refine_report_center_moves_the_reported_box_not_the_track
  tracker::tests::box_refine_report_center_recentres_a_box_given_off_the_target
  tracker::tests::box_refine_survives_a_box_at_the_frame_edge_and_tiny_frames
  tracker::tests::the_drift_check_flags_a_box_left_on_background
  tracker::tests::the_first_frame_filter_answers_drift_checks_only_on_the_visible_target
  tracker::tests::the_learned_box_head_answers_drift_checks_only_on_the_visible_target
  tracker::tests::the_verifier_confirms_unconfident_frames_on_the_target
  tracker::tests::the_verifier_looks_first_where_the_frozen_filter_points
  tracker::tests::the_verifier_looks_first_where_the_template_match_points
  tracker::tests::with_a_verifier_the_filter_sweeps_the_frame_only_when_asked
)
listed=$("${qemu[@]}" "$core_tests" --list --format terse) || fail "listing bevt_core's unit tests under qemu"
skip_args=()
for t in "${skipped[@]}"; do
  # A renamed or deleted test must leave this list too.
  grep -qxF "$t: test" <<<"$listed" || fail "no unit test $t in bevt_core (update the list)"
  echo "test-aarch64: not run under qemu (long tracker runs, listed above; run natively): $t" >&2
  skip_args+=(--skip "$t")
done

if [ "$programs" = 1 ]; then
  step "--help of the aarch64 programs under qemu"
  for prog in bevt_node bevt; do
    help=$("${qemu[@]}" "$arm_bin/$prog" --help) || fail "$prog --help under qemu exited with $?"
    grep -q '^Usage:' <<<"$help" || fail "$prog --help under qemu printed no usage line"
  done
else
  echo "test-aarch64: AARCH64_PROGRAMS=0: bevt_node and bevt are not built for aarch64 in this run; bevt_core's example track_sequence tracks the sequence" >&2
fi

# The native `bevt` as `cargo test --workspace` (README's test command) builds it for the
# integration tests, in that command's environment (the caller's CARGO_INCREMENTAL, not the 0
# exported above for the cross build: it is part of the local crates' fingerprints): under CI
# that command has just run, so this is a no-op. Before, `cargo build -p bevt_node` here compiled RustDDS, ros2-client,
# bevt_core and bevt_node again (over 2 minutes of CI on 2026-11-26).
step "native bevt (x86_64), as the test command builds it"
"${native_incremental[@]}" cargo test --locked --workspace --no-run -q || fail "native build"
native_bin="$target_dir/debug"
[ -x "$native_bin/bevt" ] || fail "no native bevt at $native_bin/bevt"
[ "$programs" = 1 ] || [ -x "$native_bin/examples/track_sequence" ] ||
  fail "no native track_sequence in $native_bin/examples (cargo test builds the examples)"

# The unit tests beside the evals; their output is printed once both are done.
step "bevt_core unit tests under ${qemu[*]}, beside the sequence's two runs"
# Run from the package's folder, as `cargo test` would. A time limit, so that a hang (e.g.
# a glibc mismatch, scripts/build-aarch64.sh) fails the step instead of stalling CI: about
# 25x the time the tests take (docs/testing.md#ci).
(cd bevt_core && exec timeout "$QEMU_TIMEOUT_S" "${qemu[@]}" "$core_tests" -q --exact "${skip_args[@]}") \
  >"$work/unit.log" 2>&1 &
unit_pid=$!

if [ "$programs" = 1 ]; then
  step "bevt eval --sequences $sequence: x86_64, then aarch64 under qemu"
  "$native_bin/bevt" eval --dataset "$dataset" --sequences "$sequence" --out "$work/x86_64" \
    >"$work/x86_64.log" 2>&1 || { cat "$work/x86_64.log" >&2; fail "native bevt eval"; }
  timeout "$QEMU_TIMEOUT_S" "${qemu[@]}" "$arm_bin/bevt" eval --dataset "$dataset" \
    --sequences "$sequence" --out "$work/aarch64" >"$work/aarch64.log" 2>&1 ||
    { rc=$?; cat "$work/aarch64.log" >&2; fail "aarch64 bevt eval under qemu (exit $rc)"; }
else
  # The sequence's first box and frames from the dataset's manifest, as `bevt eval` reads
  # them (UAV123 layout: img_dir/<frame number, nz digits>.<ext>, start_frame..end_frame).
  python3 - "$dataset" "$sequence" >"$work/args" <<'EOF' ||
import json
import os
import re
import sys

root, name = sys.argv[1], sys.argv[2]
with open(os.path.join(root, "sequences.json")) as f:
    seqs = [s for s in json.load(f)["sequences"] if s["name"] == name]
if len(seqs) != 1:
    sys.exit(f"{len(seqs)} sequences named {name} in sequences.json")
s = seqs[0]
with open(os.path.join(root, s["anno"])) as f:
    first = [v for v in re.split(r"[,\s]+", f.readline().strip()) if v]
if len(first) != 4:
    sys.exit(f"{s['anno']}: the first row is not x,y,w,h")
print(",".join(first))
nz, ext = s.get("nz", 6), s.get("ext", "jpg")
for n in range(s.get("start_frame", 1), s["end_frame"] + 1):
    p = os.path.join(root, s["img_dir"], f"{n:0{nz}d}.{ext}")
    if not os.path.isfile(p):
        sys.exit(f"missing frame {p}")
    print(p)
EOF
    fail "cannot resolve $sequence in $dataset/sequences.json"
  mapfile -t seq_args <"$work/args"
  mkdir -p "$work/x86_64" "$work/aarch64"
  step "track_sequence $sequence ($((${#seq_args[@]} - 1)) frames): x86_64, then aarch64 under qemu"
  "$native_bin/examples/track_sequence" "$work/x86_64/$sequence" "${seq_args[@]}" \
    >"$work/x86_64.log" 2>&1 || { cat "$work/x86_64.log" >&2; fail "native track_sequence"; }
  timeout "$QEMU_TIMEOUT_S" "${qemu[@]}" "$arm_bin/examples/track_sequence" \
    "$work/aarch64/$sequence" "${seq_args[@]}" >"$work/aarch64.log" 2>&1 ||
    { rc=$?; cat "$work/aarch64.log" >&2; fail "aarch64 track_sequence under qemu (exit $rc)"; }
fi

step "the unit tests under qemu"
rc=0
wait "$unit_pid" || rc=$?
unit_pid=
cat "$work/unit.log" >&2
[ "$rc" = 0 ] || fail "bevt_core's unit tests under qemu (exit $rc; 124: not done in $QEMU_TIMEOUT_S s)"

step "compare track states (equal) and boxes (tolerance $tolerance px)"
python3 - "$work/x86_64/$sequence.state.csv" "$work/aarch64/$sequence.state.csv" <<'EOF' ||
import csv
import sys

def states(path):
    try:
        with open(path, newline="") as f:
            return [(row["frame"], row["state"]) for row in csv.DictReader(f)]
    except (OSError, KeyError, csv.Error) as e:
        sys.exit(f"cannot read track states: {e}")

x86, arm = states(sys.argv[1]), states(sys.argv[2])
if not x86 or x86 != arm:
    diff = next((f"frame {a[0]}: {a[1]} on x86_64, {b[1]} on aarch64"
                 for a, b in zip(x86, arm) if a != b), f"{len(x86)} / {len(arm)} rows")
    sys.exit(f"the track states differ ({diff})")
print(f"test-aarch64: {len(x86)} track states equal", file=sys.stderr)
EOF
  fail "track states of $sequence"
python3 - "$work/x86_64/$sequence.txt" "$work/aarch64/$sequence.txt" "$tolerance" <<'EOF' ||
import math
import sys

def boxes(path):
    rows = []
    try:
        with open(path) as f:
            for n, line in enumerate(f, start=1):
                line = line.strip()
                if line:
                    row = [float(v) for v in line.replace("\t", ",").split(",")]
                    if not all(math.isfinite(v) for v in row):
                        sys.exit(f"{path}:{n}: not a finite box: {line}")
                    rows.append(row)
    except (OSError, ValueError) as e:
        sys.exit(f"cannot read boxes: {e}")
    return rows

x86, arm, tol = boxes(sys.argv[1]), boxes(sys.argv[2]), float(sys.argv[3])
if not x86:
    sys.exit(f"no boxes in {sys.argv[1]}")
if len(x86) != len(arm):
    sys.exit(f"{len(x86)} x86_64 boxes but {len(arm)} aarch64 boxes")
worst, worst_frame, differ = 0.0, 0, 0
for i, (a, b) in enumerate(zip(x86, arm), start=1):
    if len(a) != 4 or len(b) != 4:
        sys.exit(f"frame {i}: not an x,y,w,h box ({a} / {b})")
    d = max(abs(p - q) for p, q in zip(a, b))
    differ += d > 0
    if d > worst:
        worst, worst_frame = d, i
print(f"test-aarch64: {len(x86)} boxes, {differ} differ, largest difference {worst:g} px"
      + (f" (frame {worst_frame})" if differ else ""), file=sys.stderr)
if worst > tol:
    sys.exit(f"frame {worst_frame}: aarch64 and x86_64 boxes differ by {worst:g} px, "
             f"more than the tolerance {tol:g} px")
EOF
  fail "boxes of $sequence"
step "passed"
