#!/usr/bin/env bash
# Counts the instructions a program executes, for the aarch64 speed estimate of
# docs/deploy.md (an emulator cannot time a Jetson; it can count its instructions).
#
# Usage: scripts/insn-count.sh aarch64|x86_64 PROGRAM [ARGS...]
#   aarch64  PROGRAM (an aarch64 binary) under qemu-aarch64 with the counting plugin
#            scripts/insn-count/insn_count.c (compiled here with the host's gcc)
#   x86_64   PROGRAM (a native binary) under qemu-x86_64 with the same plugin: the same
#            counter for both architectures. (valgrind --tool=callgrind's `I refs` is the
#            native cross-check; perf's instruction counter is not offered in this VM.)
# Prints `insns N` last, on stdout; the program's own output goes to stderr.
set -euo pipefail
arch=${1:?usage: insn-count.sh aarch64|x86_64 PROGRAM [ARGS...]}
shift
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
gcc -shared -fPIC -O2 -Wall -Wextra -o "$work/insn_count.so" "$here/insn-count/insn_count.c"
case "$arch" in
  # The cross glibc pinned, as scripts/build-aarch64.sh explains ($BEVT_QEMU_AARCH64).
  aarch64) qemu=(qemu-aarch64 -L /usr/aarch64-linux-gnu
             -E LD_LIBRARY_PATH=/usr/aarch64-linux-gnu/lib:/usr/lib/aarch64-linux-gnu) ;;
  x86_64) qemu=(qemu-x86_64) ;;
  *) echo "insn-count: unknown architecture '$arch' (aarch64 or x86_64)" >&2; exit 2 ;;
esac
"${qemu[@]}" -plugin "$work/insn_count.so" -d plugin -D "$work/count.txt" "$@" >&2
tail -n 1 "$work/count.txt"
