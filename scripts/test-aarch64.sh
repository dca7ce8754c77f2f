#!/usr/bin/env bash
# The aarch64 build tested under user-mode emulation (qemu-aarch64), against the x86_64 build:
#   1. bevt_core's unit tests, cross-built for aarch64-unknown-linux-gnu, run under qemu;
#   2. `bevt_node --help` and `bevt --help` of the cross-built programs;
#   3. `bevt eval` on one dev sequence (default wakeboard7) by the aarch64 `bevt` under qemu
#      and by the native x86_64 `bevt`; every box must agree within TOLERANCE_PX pixels
#      (each of x, y, w, h). They are not bit-identical: floating-point results differ by
#      ulps between the architectures (glibc's libm, rustfft's NEON and x86 paths), and the
#      tracker feeds each frame's box into the next. wakeboard7 on 2026-11-25: boxes equal
#      for frames 1-5, largest difference 1.22 px (docs/deploy.md#aarch64-jetson). A target
#      lost on one architecture only would differ by tens of pixels.
#
# Usage: scripts/test-aarch64.sh [SEQUENCE]
# Environment:
#   BEVT_DATASET     dataset root (default ../shared/datasets/uav123_10fps_dev)
#   TOLERANCE_PX     largest allowed |aarch64 - x86_64| of a box coordinate (default below)
#   AARCH64_FEATURES cargo features of the cross-built programs (default `jazzy`: no DDS
#                    Security, so no arm64 OpenSSL to install; the tracker is the same code)
#
# Installs what is missing (rustup target, gcc-aarch64-linux-gnu, qemu-user). Nothing is
# skipped: a missing tool, dataset or sequence is an error (exit 1), as is any mismatch.
# Builds in the dev profile (the profile the tests use), so under CI the native `bevt` is the
# one `cargo test --workspace` already built.
set -euo pipefail
cd "$(dirname "$0")/.."

triple=aarch64-unknown-linux-gnu
sequence=${1:-wakeboard7}
dataset=${BEVT_DATASET:-../shared/datasets/uav123_10fps_dev}
tolerance=${TOLERANCE_PX:-3}
features=${AARCH64_FEATURES:-jazzy}

fail() { echo "test-aarch64: FAILED: $*" >&2; exit 1; }
step() { printf 'test-aarch64: %s (%ss)\n' "$1" "$SECONDS" >&2; }

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
apt_updated=
apt_install() {
  [ -n "$apt_updated" ] || { as_root apt-get update -q >/dev/null; apt_updated=1; }
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q "$@" >/dev/null
}

step "toolchain"
if ! rustup target list --installed | grep -qx "$triple"; then
  rustup target add "$triple"
fi
command -v aarch64-linux-gnu-gcc >/dev/null || apt_install gcc-aarch64-linux-gnu
command -v qemu-aarch64 >/dev/null || apt_install qemu-user
for tool in aarch64-linux-gnu-gcc qemu-aarch64; do
  command -v "$tool" >/dev/null || fail "$tool is missing after installing it"
done
[ -d "$dataset" ] || fail "no dataset at $dataset (set BEVT_DATASET)"

# shellcheck source=build-aarch64.sh
. scripts/build-aarch64.sh env
target_dir=${CARGO_TARGET_DIR:-$PWD/target}
qemu=(qemu-aarch64 -L /usr/aarch64-linux-gnu)

step "bevt_core unit tests for $triple, under ${qemu[*]}"
cargo test --locked -p bevt_core --target "$triple" --lib -q

step "build bevt_node and bevt for $triple (features: $features)"
cargo build --locked -p bevt_node --bin bevt_node --bin bevt --target "$triple" \
  --no-default-features --features "$features"
arm_bin="$target_dir/$triple/debug"
for prog in bevt_node bevt; do
  file -b "$arm_bin/$prog" | grep -q 'ARM aarch64' || fail "$arm_bin/$prog is not an aarch64 program"
  help=$("${qemu[@]}" "$arm_bin/$prog" --help) || fail "$prog --help under qemu exited with $?"
  grep -q '^Usage:' <<<"$help" || fail "$prog --help under qemu printed no usage line"
done

step "native bevt (x86_64)"
cargo build --locked -p bevt_node --bin bevt
native_bin="$target_dir/debug"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
step "bevt eval --sequences $sequence: x86_64, then aarch64 under qemu"
"$native_bin/bevt" eval --dataset "$dataset" --sequences "$sequence" --out "$work/x86_64" \
  >"$work/x86_64.log" 2>&1 || { cat "$work/x86_64.log" >&2; fail "native bevt eval"; }
"${qemu[@]}" "$arm_bin/bevt" eval --dataset "$dataset" --sequences "$sequence" \
  --out "$work/aarch64" >"$work/aarch64.log" 2>&1 ||
  { cat "$work/aarch64.log" >&2; fail "aarch64 bevt eval under qemu"; }

step "compare boxes (tolerance $tolerance px)"
python3 - "$work/x86_64/$sequence.txt" "$work/aarch64/$sequence.txt" "$tolerance" <<'EOF'
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
step "passed"
