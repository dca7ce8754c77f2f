#!/usr/bin/env bash
# Creates an SROS2-style DDS Security keystore for bevt_node with openssl only (no ROS needed),
# laid out as `ros2 security create_keystore` + `ros2 security create_enclave` lay it out:
#
#   DIR/public/{ca.cert.pem, identity_ca.cert.pem -> ca.cert.pem, permissions_ca.cert.pem -> ca.cert.pem}
#   DIR/private/{ca.key.pem, identity_ca.key.pem -> ca.key.pem, permissions_ca.key.pem -> ca.key.pem}
#   DIR/enclaves/{governance.xml, governance.p7s}
#   DIR/enclaves/<enclave>/{cert.pem, key.pem, permissions.xml, permissions.p7s,
#                           governance.p7s, identity_ca.cert.pem, permissions_ca.cert.pem}
#                           (the last three are relative symlinks, as sros2 makes them)
#
# Enclaves (identity = the enclave path, certificate subject CN=<enclave>, as sros2 does):
#   /bevt_node       the tracker: subscribes to its inputs, publishes its outputs, answers
#                    its services.
#   /ground_station  the operator: may call reinit and stop, publish on init and call the
#                    node's parameter services; reads the outputs.
#   /camera          the camera driver: may publish images.
#   /observer        authenticated but unprivileged: may read the outputs, may not command.
#
# Governance = sros2's default (policy/defaults/dds/governance.xml): unauthenticated
# participants refused, join access control on, discovery, liveliness and RTPS messages
# encrypted, every topic's data and metadata encrypted, read and write access control on.
# Permissions, documents signed with the permissions CA as S/MIME (openssl smime -sign -text).
#
# Usage: scripts/make-keystore.sh DIR [--domain ID|MIN-MAX] [--namespace NS] [--days N]
#   --domain     DDS domain(s) the governance and permissions cover; default ROS_DOMAIN_ID
#                or 0 (as sros2 does).
#   --namespace  the node's namespace (topic names in the permissions); default /.
#   --days       certificate lifetime; default 3650 (sros2's default is 10 years).
# DIR must not exist yet (nothing is overwritten). Private keys are unencrypted PEM, as
# sros2 writes them (DDS Security plugins read them without a password): protect DIR/private
# (only needed to issue more enclaves) and each enclave's key.pem like any secret.
set -euo pipefail

usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//' >&2; exit 2; }

dir=""
domain="${ROS_DOMAIN_ID:-0}"
ns="/"
days=3650
while [ $# -gt 0 ]; do
  case "$1" in
    --domain) domain="${2:?--domain needs a value}"; shift 2 ;;
    --namespace) ns="${2:?--namespace needs a value}"; shift 2 ;;
    --days) days="${2:?--days needs a value}"; shift 2 ;;
    -h|--help) usage ;;
    -*) echo "make-keystore: unknown option $1" >&2; usage ;;
    *) [ -z "$dir" ] || usage; dir="$1"; shift ;;
  esac
done
[ -n "$dir" ] || usage
if [ -e "$dir" ]; then
  echo "make-keystore: $dir exists; refusing to overwrite a keystore" >&2
  exit 1
fi
command -v openssl >/dev/null || { echo "make-keystore: openssl not found" >&2; exit 1; }

# Domain element of the governance and permission documents.
if [[ "$domain" =~ ^([0-9]+)-([0-9]+)$ ]]; then
  domains="<id_range><min>${BASH_REMATCH[1]}</min><max>${BASH_REMATCH[2]}</max></id_range>"
elif [[ "$domain" =~ ^[0-9]+$ ]]; then
  domains="<id>$domain</id>"
else
  echo "make-keystore: --domain $domain: expected ID or MIN-MAX" >&2
  exit 2
fi
# Topic prefix: "" for the root namespace, "/ns" otherwise.
[[ "$ns" == /* ]] || ns="/$ns"
ns="${ns%/}"

umask 077
mkdir -p "$dir"/{public,private,enclaves}
dir="$(cd "$dir" && pwd)"

# --- CA (one, for identities and permissions, as sros2's create_keystore makes it) ---
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 \
  -keyout "$dir/private/ca.key.pem" -out "$dir/public/ca.cert.pem" -days "$days" \
  -subj "/CN=sros2CA" -addext "basicConstraints=critical,CA:TRUE" 2>/dev/null
for role in identity_ca permissions_ca; do
  ln -s ca.cert.pem "$dir/public/$role.cert.pem"
  ln -s ca.key.pem "$dir/private/$role.key.pem"
done
chmod 644 "$dir"/public/ca.cert.pem

sign() { # sign IN.xml OUT.p7s: S/MIME with the permissions CA, clear text (as sros2)
  openssl smime -sign -text -in "$1" -out "$2" \
    -signer "$dir/public/permissions_ca.cert.pem" -inkey "$dir/private/permissions_ca.key.pem"
}

# --- Governance (sros2's default) ---
cat > "$dir/enclaves/governance.xml" <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
    xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>$domains</domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>ENCRYPT</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF
sign "$dir/enclaves/governance.xml" "$dir/enclaves/governance.p7s"

# --- Topic lists (DDS names: rt/ topics, rq/...Request and rr/...Reply services) ---
# Every ROS 2 participant: the graph topic, rosout, parameter events.
common="<topic>ros_discovery_info</topic><topic>rt/rosout</topic><topic>rt/parameter_events</topic>"
outputs="<topic>rt$ns/detections</topic><topic>rt$ns/track_status</topic><topic>rt/diagnostics</topic><topic>rt$ns/debug_image</topic>"
images="<topic>rt$ns/image_raw</topic><topic>rt$ns/image_raw/compressed</topic>"
commands_pub="<topic>rt$ns/init</topic><topic>rq$ns/reinitRequest</topic><topic>rq$ns/stopRequest</topic>"
commands_reply="<topic>rr$ns/reinitReply</topic><topic>rr$ns/stopReply</topic>"
# The node's ROS parameter services (get/set/list/describe_parameters...): setting a
# parameter re-tunes the tracker, so only the ground station may call them.
params_rq="<topic>rq$ns/bevt_node/*Request</topic>"
params_rr="<topic>rr$ns/bevt_node/*Reply</topic>"

# enclave NAME PUBLISH SUBSCRIBE: identity (key, certificate signed by the CA), permissions.
enclave() {
  local name="$1" pub="$2" sub="$3" d="$dir/enclaves${1}"
  mkdir -p "$d"
  local rel
  rel="$(realpath --relative-to="$d" "$dir")"
  ln -s "$rel/public/identity_ca.cert.pem" "$d/identity_ca.cert.pem"
  ln -s "$rel/public/permissions_ca.cert.pem" "$d/permissions_ca.cert.pem"
  ln -s "$rel/enclaves/governance.p7s" "$d/governance.p7s"
  openssl req -new -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 \
    -keyout "$d/key.pem" -out "$d/req.pem" -subj "/CN=${name//\//\\/}" 2>/dev/null
  openssl x509 -req -in "$d/req.pem" -sha256 -days "$days" \
    -CA "$dir/public/identity_ca.cert.pem" -CAkey "$dir/private/identity_ca.key.pem" \
    -set_serial "0x$(openssl rand -hex 16)" -out "$d/cert.pem" 2>/dev/null
  rm "$d/req.pem"
  # The grant is valid as long as the certificate (sros2 does the same).
  local nb na
  nb="$(date -u -d "$(openssl x509 -in "$d/cert.pem" -noout -startdate | cut -d= -f2)" +%Y-%m-%dT%H:%M:%S)"
  na="$(date -u -d "$(openssl x509 -in "$d/cert.pem" -noout -enddate | cut -d= -f2)" +%Y-%m-%dT%H:%M:%S)"
  cat > "$d/permissions.xml" <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
    xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$name">
      <subject_name>CN=$name</subject_name>
      <validity>
        <not_before>$nb</not_before>
        <not_after>$na</not_after>
      </validity>
      <allow_rule>
        <domains>$domains</domains>
        <publish><topics>$pub</topics></publish>
        <subscribe><topics>$sub</topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
EOF
  sign "$d/permissions.xml" "$d/permissions.p7s"
  chmod 644 "$d/cert.pem" "$d/permissions.xml" "$d/permissions.p7s"
}

enclave /bevt_node \
  "$common$outputs$commands_reply$params_rr" \
  "$common$images<topic>rt$ns/init</topic><topic>rq$ns/reinitRequest</topic><topic>rq$ns/stopRequest</topic>$params_rq"
enclave /ground_station \
  "$common$commands_pub$params_rq" \
  "$common$outputs$images$commands_reply$params_rr"
enclave /camera "$common$images" "$common"
enclave /observer "$common" "$common$outputs"

chmod 644 "$dir/enclaves/governance.xml" "$dir/enclaves/governance.p7s"
chmod 755 "$dir" "$dir/public" "$dir/enclaves"
find "$dir/enclaves" -mindepth 1 -type d -exec chmod 755 {} +
echo "make-keystore: keystore in $dir, enclaves /bevt_node /ground_station /camera /observer (domain $domain, namespace ${ns:-/})" >&2
