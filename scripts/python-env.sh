#!/usr/bin/env bash
# Creates (once) the project-local Python environment used by test tooling: rosbags (the
# reference CDR serializer for the golden files), cyclonedds (an independent DDS peer for
# the interop test), colcon, onnx, mcap. Prints the interpreter path.
#
# Safe to call from several tests at once: creation and installation run under an
# exclusive lock (flock on .venv.lock), and a finished environment is recognised by a stamp
# holding the requirements' checksum, so later calls return without running pip.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=.venv
stamp="$venv/.bevt-requirements.sha256"
# The test tooling's requirement files (requirements-peers.txt is the peers' benchmark
# environment, not the tests': scripts/nanotrack_peer.py makes its own).
reqs=(scripts/requirements.txt)
[ -f scripts/requirements-ros.txt ] && reqs+=(scripts/requirements-ros.txt)
want=$(cat "${reqs[@]}" | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  exec 9>.venv.lock
  flock 9
  # Another caller may have finished while this one waited.
  if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    [ -x "$venv/bin/python" ] || python3 -m venv "$venv" >&2
    for req in "${reqs[@]}"; do
      "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$req" >&2
    done
    echo "$want" >"$stamp"
  fi
  exec 9>&-
fi
echo "$PWD/$venv/bin/python"
