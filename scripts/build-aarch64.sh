#!/usr/bin/env bash
# Cross-builds the node (bevt_node) and the `bevt` tool for aarch64-unknown-linux-gnu (Jetson
# TX2 / Orin, DJI Manifold 2-G, Raspberry Pi 4/5 with a 64-bit OS) on an x86_64 Debian host.
#
# Usage: scripts/build-aarch64.sh [PROFILE] [-- CARGO_ARGS...]
#   PROFILE     `flight` (default: fat LTO, the binaries that fly), `release`, or `dev`
#               (quick to build; optimised like every profile here).
#   CARGO_ARGS  passed to `cargo build` (e.g. `-- --no-default-features --features jazzy`).
# The binaries land in <target dir>/aarch64-unknown-linux-gnu/<profile dir>/ (cargo names
# the dev profile's folder `debug`); their folder is printed last.
#
# Installs what it needs when missing, so it is safe to run again: the Rust target
# (rustup), Debian's cross linker gcc-aarch64-linux-gnu, and for DDS Security (the
# `security` feature, on by default, links OpenSSL through pkg-config) the arm64 OpenSSL
# (`dpkg --add-architecture arm64`, then libssl-dev:arm64). Debian's own mirrors serve
# arm64, so the same OpenSSL the distribution ships is linked, not a vendored copy.
# The environment for the cross build is set here, not in .cargo/config.toml, so native
# builds see no change. Source it for other cargo commands: `. scripts/build-aarch64.sh env`.
set -euo pipefail

triple=aarch64-unknown-linux-gnu

# Cross toolchain environment (cargo reads the TRIPLE-specific names only when building for
# that target, so these leave the host's build scripts and proc macros alone).
aarch64_env() {
  export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
  export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
  export CXX_aarch64_unknown_linux_gnu=aarch64-linux-gnu-g++
  export AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar
  # pkg-config (openssl-sys) reads the arm64 .pc files only; the Debian cross compiler
  # searches /usr/include/aarch64-linux-gnu (opensslconf.h) before /usr/include itself.
  export PKG_CONFIG_ALLOW_CROSS_aarch64_unknown_linux_gnu=1
  export PKG_CONFIG_LIBDIR_aarch64_unknown_linux_gnu=/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig
  # The emulator command for aarch64 programs (`cargo test` / `cargo run` for the target,
  # scripts/test-aarch64.sh, scripts/check-deb.sh). glibc's dynamic loader and its libc.so.6
  # must come from the same build of glibc: -L makes qemu start the cross toolchain's loader
  # (/usr/aarch64-linux-gnu/lib), and LD_LIBRARY_PATH makes that loader take the cross libc
  # before the multiarch libc6:arm64 that the host's ld.so.cache lists once libssl-dev:arm64
  # is installed (below). Mixed, every program that starts a thread hangs (2026-11-25:
  # libc6-arm64-cross 2.36-8cross1 against libc6:arm64 2.36-9+deb12u14). The arm64 OpenSSL
  # is then found in the multiarch folder.
  export BEVT_QEMU_AARCH64="qemu-aarch64 -L /usr/aarch64-linux-gnu -E LD_LIBRARY_PATH=/usr/aarch64-linux-gnu/lib:/usr/lib/aarch64-linux-gnu"
  export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="$BEVT_QEMU_AARCH64"
}

if [ "${1:-}" = env ]; then
  aarch64_env
  # Sourced: leave the caller's shell options alone.
  return 0 2>/dev/null || exit 0
fi

cd "$(dirname "$0")/.."
profile=${1:-flight}
case "$profile" in
  -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
  flight|release|dev) ;;
  *) echo "build-aarch64: unknown profile '$profile' (flight, release or dev)" >&2; exit 2 ;;
esac
shift || true
[ "${1:-}" = -- ] && shift

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
apt_updated=
apt_install() {
  # Wait for another apt-get (CI's Fast DDS step may run one at the same time).
  [ -n "$apt_updated" ] || { as_root apt-get -o DPkg::Lock::Timeout=600 update -q >/dev/null; apt_updated=1; }
  as_root env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -q "$@" >/dev/null
}

if ! rustup target list --installed | grep -qx "$triple"; then
  rustup target add "$triple"
fi
command -v aarch64-linux-gnu-gcc >/dev/null || apt_install gcc-aarch64-linux-gnu
command -v pkg-config >/dev/null || apt_install pkg-config
if [ ! -f /usr/lib/aarch64-linux-gnu/pkgconfig/openssl.pc ]; then
  if ! dpkg --print-foreign-architectures | grep -qx arm64; then
    as_root dpkg --add-architecture arm64
    apt_updated=
  fi
  # libssl-dev:arm64 must be the same version as the host's libssl3 (multiarch); install
  # both together so apt upgrades the host's copy when the mirror has moved on.
  apt_install libssl-dev:arm64 libssl-dev
fi

aarch64_env
target_dir=${CARGO_TARGET_DIR:-$PWD/target}
dir=$profile
[ "$profile" = dev ] && dir=debug
start=$(date +%s)
cargo build --locked -p bevt_node --bin bevt_node --bin bevt --target "$triple" \
  --profile "$profile" "$@"
out="$target_dir/$triple/$dir"
echo "build-aarch64: built bevt_node and bevt ($profile) in $(( $(date +%s) - start )) s" >&2
echo "$out"
