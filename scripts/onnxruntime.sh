#!/usr/bin/env bash
# Fetches (once) the ONNX Runtime shared library the `cnn` feature loads at run time, and
# prints its absolute path (use it as ORT_DYLIB_PATH or `features.cnn.runtime`).
#
# The library ships inside the PyPI wheel `onnxruntime==1.31.1` (member
# onnxruntime/capi/libonnxruntime.so.1.31.1; it needs only glibc and libstdc++). pip
# downloads the wheel (no install, no dependencies); unzip extracts that one member into
# the git-ignored folder .onnxruntime/. Nothing else is downloaded, and nothing at build time.
set -euo pipefail
cd "$(dirname "$0")/.."
version=1.31.1
dir=.onnxruntime
lib="$dir/libonnxruntime.so.$version"
if [ ! -f "$lib" ]; then
  mkdir -p "$dir/wheel"
  python3 -m pip download --quiet --disable-pip-version-check --no-deps \
    --only-binary=:all: "onnxruntime==$version" -d "$dir/wheel" >&2
  wheel=$(ls "$dir"/wheel/onnxruntime-"$version"-*.whl | head -n 1)
  python3 - "$wheel" "$dir" "$version" <<'PY' >&2
import sys, zipfile, shutil, os
wheel, out, version = sys.argv[1:]
member = f"onnxruntime/capi/libonnxruntime.so.{version}"
with zipfile.ZipFile(wheel) as z, z.open(member) as src, \
        open(os.path.join(out, f"libonnxruntime.so.{version}.part"), "wb") as dst:
    shutil.copyfileobj(src, dst)
PY
  mv "$lib.part" "$lib"
  rm -rf "$dir/wheel"
fi
echo "$PWD/$lib"
