#!/usr/bin/env bash
# Builds the Debian package bevt-node (bevt_node, bevt, bevt_latency, the parameters file,
# the tracker presets, the systemd unit; [package.metadata.deb] in bevt_node/Cargo.toml)
# with cargo-deb, then checks what it holds (scripts/check-deb.sh).
#
# Usage: scripts/build-deb.sh [PROFILE]
#   PROFILE  the cargo profile: `flight` (default; fat LTO, slow: the package that flies),
#            `release`, or `dev` for a quick check of the packaging (cargo-deb warns that it
#            does not support dev packages; such a package is not for a drone).
# The package is written to <target dir>/debian/<PROFILE>/bevt-node_<version>-1_<arch>.deb
# and its path printed last. Build on the Debian / Ubuntu release the companion computer
# runs: the libssl dependency is named after the build host's package (docs/deploy.md).
# Needs: cargo-deb (installed here at the pinned version when missing), dpkg-deb,
# libssl-dev and pkg-config (the `security` feature).
set -euo pipefail
cd "$(dirname "$0")/.."
profile=${1:-flight}
case "$profile" in
  -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
  -*) echo "build-deb: unknown option $profile" >&2; exit 2 ;;
esac
# cargo-deb makes the package from Cargo metadata: the one tool that does it without a
# debian/rules tree. Pinned: the check below expects its layout (e.g. the unit's folder).
cargo_deb_version=3.8.0
if ! cargo deb --version 2>/dev/null | grep -qx "cargo-deb $cargo_deb_version"; then
  cargo install --locked "cargo-deb@$cargo_deb_version"
fi
command -v dpkg-deb >/dev/null || { echo "build-deb: dpkg-deb not found (Debian's dpkg)" >&2; exit 1; }
target_dir=${CARGO_TARGET_DIR:-$PWD/target}
out="$target_dir/debian/$profile"
mkdir -p "$out"
start=$(date +%s)
# stdout of cargo-deb is the package's path; the build's progress goes to stderr.
# Other profiles are checks of the packaging: quicker, lighter compression.
fast=()
[ "$profile" = flight ] || fast=(--fast)
deb=$(cargo deb -p bevt_node --profile "$profile" "${fast[@]}" --output "$out/" | tail -n 1)
echo "build-deb: built $deb in $(( $(date +%s) - start )) s" >&2
scripts/check-deb.sh "$deb" "$profile"
echo "$deb"
