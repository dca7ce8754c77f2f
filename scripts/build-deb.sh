#!/usr/bin/env bash
# Builds the Debian package bevt-node (bevt_node, bevt, bevt_latency, the parameters file,
# the tracker presets, the systemd unit; [package.metadata.deb] in bevt_node/Cargo.toml)
# with cargo-deb, then checks what it holds (scripts/check-deb.sh).
#
# Usage: scripts/build-deb.sh [--target aarch64-unknown-linux-gnu] [PROFILE]
#   --target  cross-build the arm64 package (Jetson, Manifold 2-G) on an x86_64 Debian host:
#             the binaries are built by scripts/build-aarch64.sh (which installs the cross
#             linker and the arm64 OpenSSL through multiarch), then packaged with
#             `cargo deb --no-build --target`. Without it, the host's own architecture.
#   PROFILE   the cargo profile: `flight` (default; fat LTO, slow: the package that flies),
#             `release`, or `dev` for a quick check of the packaging (cargo-deb warns that it
#             does not support dev packages; such a package is not for a drone).
# The package is written to <target dir>/debian/<PROFILE>/bevt-node_<version>-1_<arch>.deb
# (<target dir>/debian/<triple>/<PROFILE>/ with --target) and its path printed last. Build
# on the Debian / Ubuntu release the companion computer runs: the libssl dependency is named
# after the build host's package (docs/deploy.md).
# Needs: cargo-deb (installed here at the pinned version when missing), dpkg-deb,
# dpkg-shlibdeps (dpkg-dev), libssl-dev and pkg-config (the `security` feature); with
# --target, qemu-user too (scripts/check-deb.sh runs the arm64 programs under it).
set -euo pipefail
cd "$(dirname "$0")/.."
usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }
target=
profile=flight
while [ $# -gt 0 ]; do
  case "$1" in
    -h|--help) usage; exit 0 ;;
    --target) target=${2:?build-deb: --target needs a triple}; shift 2 ;;
    --target=*) target=${1#--target=}; shift ;;
    -*) echo "build-deb: unknown option $1" >&2; exit 2 ;;
    *) profile=$1; shift ;;
  esac
done
case "$target" in
  ''|aarch64-unknown-linux-gnu) ;;
  *) echo "build-deb: --target $target is not supported (aarch64-unknown-linux-gnu only)" >&2; exit 2 ;;
esac
# cargo-deb makes the package from Cargo metadata: the one tool that does it without a
# debian/rules tree. Pinned: the check below expects its layout (e.g. the unit's folder).
cargo_deb_version=3.8.0
if ! cargo deb --version 2>/dev/null | grep -qx "cargo-deb $cargo_deb_version"; then
  cargo install --locked "cargo-deb@$cargo_deb_version"
fi
command -v dpkg-deb >/dev/null || { echo "build-deb: dpkg-deb not found (Debian's dpkg)" >&2; exit 1; }
target_dir=${CARGO_TARGET_DIR:-$PWD/target}
out="$target_dir/debian/${target:+$target/}$profile"
mkdir -p "$out"
start=$(date +%s)
# Other profiles are checks of the packaging: quicker, lighter compression.
fast=()
[ "$profile" = flight ] || fast=(--fast)
if [ -z "$target" ]; then
  # stdout of cargo-deb is the package's path; the build's progress goes to stderr.
  deb=$(cargo deb -p bevt_node --profile "$profile" "${fast[@]}" --output "$out/" | tail -n 1)
else
  # The default features (DDS Security included), all three programs; build-aarch64.sh
  # prints the binaries' folder last.
  scripts/build-aarch64.sh "$profile" -- --bin bevt_latency >/dev/null
  # shellcheck source=build-aarch64.sh
  . scripts/build-aarch64.sh env
  # cargo-deb maps the assets' target/release/ to target/<triple>/<profile>/, strips with
  # aarch64-linux-gnu-strip, names the architecture arm64 and computes Depends ($auto) with
  # dpkg-shlibdeps from the arm64 libraries multiarch installed (libc6:arm64, libssl3:arm64).
  deb=$(cargo deb -p bevt_node --no-build --target "$target" --profile "$profile" "${fast[@]}" \
    --output "$out/" | tail -n 1)
fi
echo "build-deb: built $deb in $(( $(date +%s) - start )) s" >&2
scripts/check-deb.sh "$deb" "$profile"
echo "$deb"
