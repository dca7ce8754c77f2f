#!/usr/bin/env bash
# Creates (once) the project-local Python environment used by test tooling: rosbags (the
# reference CDR serializer for the golden files) and cyclonedds (an independent DDS peer
# for the interop test). Prints the interpreter path.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=.venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv" >&2
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r scripts/requirements.txt >&2
echo "$PWD/$venv/bin/python"
