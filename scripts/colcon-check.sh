#!/usr/bin/env bash
# Checks that colcon (from PyPI, no ROS installation) builds bevt_node as an ament_cargo
# package and installs its executables where `ros2 run bevt_node bevt_node` looks for them.
#
# colcon-ros-cargo passes `--target-dir <build-base>/bevt_node` to cargo; that folder is made
# a link to this workspace's target/ so colcon reuses what cargo already built instead of
# compiling everything a second time. The cargo profile is the first argument (default
# `dev`, what `cargo test --workspace` just built in CI; `flight` for the binaries that fly).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
profile=${1:-dev}
py=$(scripts/python-env.sh)
if ! command -v cargo-ament-build >/dev/null 2>&1; then
  cargo install --locked cargo-ament-build@0.1.11
fi
# cargo-ament-build looks for the binaries in target/<profile name>, except for the dev
# profile, whose folder is target/debug: pass no profile for dev. The dev build is the one
# `cargo test --workspace` made, whose bevt_node has the `cnn` feature (bevt_tests' default):
# the same feature here, or cargo would compile bevt_core and bevt_node again without it. The
# flight binaries are built as they ship, without it.
if [ "$profile" = dev ]; then
  cargo_args=(--cargo-args --features cnn)
else
  cargo_args=(--cargo-args --profile "$profile")
fi
ws=$(mktemp -d)
trap 'rm -rf "$ws"' EXIT
mkdir -p "$ws/build" "$root/target"
ln -s "$root/target" "$ws/build/bevt_node"
(cd "$ws" && "$(dirname "$py")/colcon" build --base-paths "$root/bevt_node" --packages-select bevt_node \
   "${cargo_args[@]}" > "$ws/colcon.log" 2>&1) || { cat "$ws/colcon.log"; exit 1; }
for exe in bevt_node bevt bevt_latency; do
  test -x "$ws/install/bevt_node/lib/bevt_node/$exe" || { echo "colcon did not install $exe"; ls -R "$ws/install"; exit 1; }
done
share="$ws/install/bevt_node/share/bevt_node"
test -f "$share/package.xml"
# The launch file, the parameters file and every tracker preset are installed with it.
for f in launch/bevt.launch.py config/node.yaml config/bevt.yaml config/cnn_fusion.yaml; do
  test -f "$share/$f" || { echo "colcon did not install share/bevt_node/$f"; exit 1; }
done
"$py" -m py_compile "$share/launch/bevt.launch.py"
# launch / launch_ros are not on PyPI, so the launch file cannot be run here (docs/ros.md says
# how it was run by hand): read it instead. Its arguments must be the four docs/ros.md
# documents, and its Node must name this package and an executable colcon installed.
"$py" - "$share/launch/bevt.launch.py" "$ws/install/bevt_node/lib/bevt_node" <<'EOF'
import ast
import os
import sys

path, libdir = sys.argv[1], sys.argv[2]
tree = ast.parse(open(path).read(), path)
args = None
node_kw = {}
for node in ast.walk(tree):
    if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "ARGUMENTS" for t in node.targets):
        args = [elt.elts[0].value for elt in node.value.elts]
    if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "Node":
        node_kw = {k.arg: k.value for k in node.keywords}
want = ["params_file", "namespace", "image_topic", "respawn"]
if args != want:
    sys.exit(f"{path}: launch arguments {args}, expected {want}")
for key in ("package", "executable"):
    value = getattr(node_kw.get(key), "value", None)
    if value != "bevt_node":
        sys.exit(f"{path}: Node({key}={value!r}), expected 'bevt_node'")
if not os.access(os.path.join(libdir, "bevt_node"), os.X_OK):
    sys.exit(f"the launch file's executable is not installed in {libdir}")
EOF
# The installed executable runs (and rejects a bad argument with a clear message).
out=$("$ws/install/bevt_node/lib/bevt_node/bevt_node" --bogus-flag 2>&1 || true)
grep -q "unknown argument" <<<"$out"
echo "colcon: bevt_node ($profile profile) installed to install/bevt_node/lib/bevt_node/ (bevt_node, bevt, bevt_latency)"
