#!/usr/bin/env bash
# Soak benchmark of the ROS 2 node (issue 11): builds the node and the soak driver in
# release, copies both to OUT_DIR (so later builds cannot replace them mid-run) and runs
#   bevt_soak --duration SECONDS [more bevt_soak options]
# with the output in OUT_DIR/soak.log and one CSV row per minute in OUT_DIR/soak.csv.
#
#   scripts/soak.sh [OUT_DIR] [SECONDS] [bevt_soak options...]
#   e.g. scripts/soak.sh /tmp/soak 3600 --hostile-share 0.05 --reinit-period 30
#
# Defaults: OUT_DIR=target/soak, SECONDS=3600. Foreground; wrap in `nohup ... &` for a
# long run. The node runs as its own process (bevt_node_under_test); see the header of
# tests/bin/bevt_soak.rs for what is sent and measured.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/soak}
secs=${2:-3600}
shift $(( $# > 2 ? 2 : $# ))
mkdir -p "$out/bin"
cargo build --release -q -p bevt_tests --bin bevt_soak --bin bevt_node_under_test
cp target/release/bevt_soak target/release/bevt_node_under_test "$out/bin/"
{
  echo "# $(date -u +%FT%TZ) $(uname -srm), $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "# git $(git rev-parse --short HEAD 2>/dev/null || echo '?'); bevt_soak --duration $secs $*"
} > "$out/soak.log"
"$out/bin/bevt_soak" --duration "$secs" --csv "$out/soak.csv" "$@" 2>&1 | tee -a "$out/soak.log"
