#!/usr/bin/env bash
# Checks that colcon (from PyPI, no ROS installation) builds bevt_node as an ament_cargo
# package and installs its executables where `ros2 run bevt_node bevt_node` looks for them.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
py=$(scripts/python-env.sh)
if ! command -v cargo-ament-build >/dev/null 2>&1; then
  cargo install --locked cargo-ament-build@0.1.11
fi
ws=$(mktemp -d)
trap 'rm -rf "$ws"' EXIT
(cd "$ws" && "$(dirname "$py")/colcon" build --base-paths "$root/bevt_node" --packages-select bevt_node \
   > "$ws/colcon.log" 2>&1) || { cat "$ws/colcon.log"; exit 1; }
for exe in bevt_node bevt bevt_latency; do
  test -x "$ws/install/bevt_node/lib/bevt_node/$exe" || { echo "colcon did not install $exe"; ls -R "$ws/install"; exit 1; }
done
test -f "$ws/install/bevt_node/share/bevt_node/package.xml"
# The installed executable runs (and rejects a bad argument with a clear message).
out=$("$ws/install/bevt_node/lib/bevt_node/bevt_node" --bogus-flag 2>&1 || true)
grep -q "unknown argument" <<<"$out"
echo "colcon: bevt_node installed to install/bevt_node/lib/bevt_node/ (bevt_node, bevt, bevt_latency)"
