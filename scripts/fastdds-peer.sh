#!/usr/bin/env bash
# Builds (once; again when its sources change) the Fast DDS interop peer of the
# integration tests, tests/fastdds/peer.cpp, into target/fastdds-peer/ (git-ignored), and
# prints the peer's path. Uses Debian's packages libfastrtps-dev (Fast DDS 2.9, the
# middleware of ROS 2's default RMW), fastddsgen (type support from
# tests/fastdds/ros_types.idl), cmake and g++; installs them with apt-get when missing and
# running as root, unless --no-install (the integration test's way: tests never install).
# Exits non-zero with the reason on stderr when the peer cannot be built.
set -euo pipefail
install=1
[ "${1:-}" = --no-install ] && install=0
cd "$(dirname "$0")/.."
src=tests/fastdds
out=target/fastdds-peer
packages=(libfastrtps-dev fastddsgen cmake g++)

have_tools() {
  command -v fastddsgen >/dev/null && command -v cmake >/dev/null && command -v g++ >/dev/null &&
    [ -f /usr/include/fastdds/dds/domain/DomainParticipant.hpp ]
}

if ! have_tools; then
  if [ "$install" = 0 ]; then
    echo "fastdds-peer: Fast DDS tools missing (${packages[*]}); scripts/fastdds-peer.sh installs them with apt-get" >&2
    exit 1
  fi
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
    echo "fastdds-peer: Fast DDS tools missing and cannot install them (needs root and apt-get): apt-get install ${packages[*]}" >&2
    exit 1
  fi
  echo "fastdds-peer: installing ${packages[*]} with apt-get" >&2
  export DEBIAN_FRONTEND=noninteractive
  # -o DPkg::Lock::Timeout: wait for another apt-get (CI's background aarch64 build may run
  # one at the same time) instead of failing.
  apt=(apt-get -o DPkg::Lock::Timeout=240)
  if ! timeout 300 "${apt[@]}" install -y --no-install-recommends "${packages[@]}" >&2; then
    timeout 120 "${apt[@]}" update >&2 || true
    if ! timeout 300 "${apt[@]}" install -y --no-install-recommends "${packages[@]}" >&2; then
      echo "fastdds-peer: apt-get install ${packages[*]} failed" >&2
      exit 1
    fi
  fi
  have_tools || { echo "fastdds-peer: tools still missing after apt-get install" >&2; exit 1; }
fi

mkdir -p "$out/gen" "$out/build"
if [ ! -f "$out/gen/ros_typesPubSubTypes.cxx" ] || [ "$src/ros_types.idl" -nt "$out/gen/ros_typesPubSubTypes.cxx" ]; then
  # -cs: type Pose_ and member pose_ differ only in case.
  fastddsgen -cs -replace -d "$out/gen" "$src/ros_types.idl" >&2
fi
# A build tree configured for another checkout (a copied target/) is started afresh.
if ! grep -qx "CMAKE_HOME_DIRECTORY:INTERNAL=$PWD/$src" "$out/build/CMakeCache.txt" 2>/dev/null; then
  rm -rf "$out/build"
  mkdir -p "$out/build"

  cmake -S "$src" -B "$out/build" -DCMAKE_BUILD_TYPE=Release -DGEN_DIR="$PWD/$out/gen" >&2
fi
cmake --build "$out/build" -j 2 >&2
echo "$PWD/$out/build/bevt_fastdds_peer"
