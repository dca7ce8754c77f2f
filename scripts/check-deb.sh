#!/usr/bin/env bash
# Checks a bevt-node .deb (scripts/build-deb.sh makes one): `dpkg-deb --contents` must list
# the binaries, the parameters file, every tracker preset of config/, the systemd unit, the
# sysusers.d user and the licences; `dpkg-deb --info` must show the conffiles, a libssl
# dependency and the maintainer scripts that create the user and reload systemd; the
# packaged bevt_node must run (`--help`). The package's Architecture (amd64 or arm64) must be
# the machine of every packaged program (ELF x86-64 or ARM aarch64); a package for another
# architecture than this host's is run under qemu-user (arm64: qemu-aarch64 with the cross
# glibc and the multiarch arm64 libraries). Prints the package's and the binaries' sizes, and
# for the flight profile fails if a binary is 30 MB or larger (issue 21).
#
# Usage: scripts/check-deb.sh DEB [PROFILE]
set -euo pipefail
cd "$(dirname "$0")/.."
deb=${1:?usage: scripts/check-deb.sh DEB [PROFILE]}
profile=${2:-flight}
test -f "$deb" || { echo "check-deb: $deb: no such file" >&2; exit 1; }
fail=0
problem() { echo "check-deb: $*" >&2; fail=1; }

contents=$(dpkg-deb --contents "$deb")
info=$(dpkg-deb --info "$deb")
# Paths as dpkg-deb lists them (./usr/bin/bevt_node), files only.
listed=$(awk '$1 !~ /^d/ {print $6}' <<<"$contents")

want=(
  ./usr/bin/bevt_node ./usr/bin/bevt ./usr/bin/bevt_latency
  ./etc/bevt_node/node.yaml ./etc/default/bevt-node
  ./usr/lib/systemd/system/bevt-node.service ./usr/lib/sysusers.d/bevt-node.conf
  ./usr/share/doc/bevt-node/copyright ./usr/share/doc/bevt-node/LICENSE-MIT
  ./usr/share/doc/bevt-node/LICENSE-APACHE ./usr/share/doc/bevt-node/nanotrack/LICENSE
  ./usr/share/doc/bevt-node/rustdds/LICENSE.md ./usr/share/doc/bevt-node/deploy.md
)
for preset in config/*.yaml; do
  want+=("./usr/share/bevt_node/$preset")
done
for f in "${want[@]}"; do
  grep -qxF "$f" <<<"$listed" || problem "missing from the package: ${f#.}"
done
for f in /etc/bevt_node/node.yaml /etc/default/bevt-node; do
  dpkg-deb --ctrl-tarfile "$deb" | tar -xO ./conffiles 2>/dev/null | grep -qxF "$f" \
    || problem "not a conffile: $f"
done
depends=$(sed -n 's/^ Depends: //p' <<<"$info")
grep -Eq '(^|, )libssl[0-9.]+(t64)?( |,|$)' <<<"$depends" \
  || problem "no libssl in Depends ($depends): the security feature links the system OpenSSL"
grep -q systemd <<<"$depends" || problem "no systemd in Depends ($depends)"
postinst=$(dpkg-deb --ctrl-tarfile "$deb" | tar -xO ./postinst 2>/dev/null || true)
grep -q "systemd-sysusers" <<<"$postinst" || problem "postinst does not create the bevt-node user"
grep -q "daemon-reload" <<<"$postinst" || problem "postinst does not reload systemd"

# The unit runs what the package installs, with the parameters file it installs.
x=$(mktemp -d)
trap 'rm -rf "$x"' EXIT
dpkg-deb -x "$deb" "$x"
unit="$x/usr/lib/systemd/system/bevt-node.service"
if [ -f "$unit" ]; then
  grep -qx 'ExecStart=/usr/bin/bevt_node --ros-args --params-file /etc/bevt_node/node.yaml' "$unit" \
    || problem "the unit's ExecStart is not the packaged node with /etc/bevt_node/node.yaml"
  grep -qx 'Restart=on-failure' "$unit" || problem "the unit does not restart on failure"
  grep -q '^PrivateNetwork=' "$unit" && problem "the unit sets PrivateNetwork= (DDS needs the network)"
  if command -v systemd-analyze >/dev/null; then
    # Offline check of the unit's syntax (the binary it names is in the extracted tree).
    sed "s#/usr/bin/bevt_node#$x/usr/bin/bevt_node#" "$unit" > "$x/bevt-node.service"
    systemd-analyze verify "$x/bevt-node.service" || problem "systemd-analyze verify failed"
  fi
fi
cmp -s "$x/etc/bevt_node/node.yaml" config/node.yaml || problem "/etc/bevt_node/node.yaml differs from config/node.yaml"

# The architecture the control file names is the one the programs were built for.
arch=$(dpkg-deb --field "$deb" Architecture)
run=()
case "$arch" in
  amd64) machine='x86-64' ;;
  arm64) machine='ARM aarch64' ;;
  *) problem "Architecture: $arch (amd64 or arm64 expected)"; machine='?' ;;
esac
if [ "$arch" = arm64 ] && [ "$(dpkg --print-architecture)" != arm64 ]; then
  # The cross glibc, and the arm64 OpenSSL where multiarch put it (scripts/build-aarch64.sh).
  # shellcheck source=build-aarch64.sh
  . scripts/build-aarch64.sh env
  read -ra run <<<"$BEVT_QEMU_AARCH64"
  command -v qemu-aarch64 >/dev/null || problem "qemu-aarch64 (Debian's qemu-user) is needed to run the arm64 programs"
fi
for b in bevt_node bevt bevt_latency; do
  f="$x/usr/bin/$b"
  [ -f "$f" ] || continue
  file -b "$f" | grep -q "ELF 64-bit LSB .*, $machine,"     || problem "/usr/bin/$b is not an $arch program: $(file -b "$f" | cut -d, -f1-2)"
done
if [ -x "$x/usr/bin/bevt_node" ]; then
  "${run[@]}" "$x/usr/bin/bevt_node" --help | grep -q -- "--params-file" \
    || problem "the packaged bevt_node --help failed${run[*]:+ under ${run[*]}}"
  "${run[@]}" "$x/usr/bin/bevt" --help | grep -q '^Usage:' \
    || problem "the packaged bevt --help failed${run[*]:+ under ${run[*]}}"
fi

limit=$((30 * 1000 * 1000))
echo "check-deb: $(basename "$deb"): $(stat -c %s "$deb") bytes ($profile profile, $arch)"
for b in bevt_node bevt bevt_latency; do
  f="$x/usr/bin/$b"
  [ -f "$f" ] || continue
  size=$(stat -c %s "$f")
  echo "check-deb:   /usr/bin/$b $size bytes"
  if [ "$profile" = flight ] && [ "$size" -ge "$limit" ]; then
    problem "/usr/bin/$b is $size bytes: flight binaries must stay under 30 MB"
  fi
done
echo "check-deb:   Depends: $depends"
[ "$fail" = 0 ] || exit 1
echo "check-deb: ok"
