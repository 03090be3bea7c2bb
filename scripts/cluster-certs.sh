#!/usr/bin/env bash
# Makes a cluster CA and one certificate per node for mutual TLS between Tessera nodes
# (docs/operations.md, "Running a cluster across hosts securely").
#
#   scripts/cluster-certs.sh DIR NAME[=ALT,ALT...] ...
#
# In DIR (made with mode 700 if missing):
#   ca.pem, ca.key       the cluster CA: an EC P-256 key and a self-signed certificate (CA_DAYS,
#                        default 1825 days). Made once: when DIR holds them already they are
#                        reused (to add nodes later), never overwritten.
#   NAME.pem, NAME.key   one node's key and certificate signed by the CA (DAYS, default 825), for
#                        TLS server and client use; subjectAltName: NAME and the ALTs, each as
#                        an IP address if it is one, else as a DNS name. A node whose files exist
#                        is left alone (remove both to reissue).
# The subjects name only the CA's date and the node (a TLS server shows its certificate to any
# client that connects, before that client has shown its own). Keys are written with mode 600. Each node needs ca.pem, its NAME.pem and its NAME.key
# (settings cluster-tls-ca, cluster-tls-cert, cluster-tls-key); ca.key belongs on no node.
set -euo pipefail

usage() {
  echo "usage: $0 DIR NAME[=ALT,ALT...] ..." >&2
  echo "  NAME: a host name, an IP address or any label of [A-Za-z0-9._-] (the file name);" >&2
  echo "  ALT: further host names or IP addresses of that node" >&2
  exit 2
}
(( $# >= 2 )) || usage
command -v openssl > /dev/null || { echo "$0: the openssl command is missing (apt-get install openssl)" >&2; exit 1; }
dir=$1; shift
CA_DAYS=${CA_DAYS:-1825}
DAYS=${DAYS:-825}
umask 077

# An IPv4 or IPv6 address (subjectAltName IP:) or else a DNS name (DNS:).
san_entry() {
  if [[ $1 =~ ^[0-9]{1,3}(\.[0-9]{1,3}){3}$ || $1 == *:* ]]; then echo "IP:$1"; else echo "DNS:$1"; fi
}
valid_name() { [[ $1 =~ ^[A-Za-z0-9][A-Za-z0-9._-]*$ ]]; }
valid_alt() { [[ $1 =~ ^[A-Za-z0-9][A-Za-z0-9.:_-]*$ ]]; }

# Check every argument before writing anything.
for spec in "$@"; do
  name=${spec%%=*}
  valid_name "$name" || { echo "$0: '$name' is not a node name of [A-Za-z0-9._-]" >&2; exit 2; }
  [[ $name != ca ]] || { echo "$0: 'ca' is the CA's file name, not a node name" >&2; exit 2; }
  if [[ $spec == *=* ]]; then
    IFS=, read -r -a alts <<< "${spec#*=}"
    for a in "${alts[@]}"; do valid_alt "$a" || { echo "$0: '$a' (of $name) is not a host name or address" >&2; exit 2; }; done
  fi
done

mkdir -p "$dir"
chmod 700 "$dir"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

if [[ -e $dir/ca.pem || -e $dir/ca.key ]]; then
  [[ -f $dir/ca.pem && -f $dir/ca.key ]] ||
    { echo "$0: $dir holds only one of ca.pem and ca.key: refusing to make a new CA over it" >&2; exit 1; }
  echo "using the existing CA $dir/ca.pem"
else
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$dir/ca.key" 2> "$tmp/err" ||
    { cat "$tmp/err" >&2; exit 1; }
  openssl req -new -x509 -key "$dir/ca.key" -sha256 -days "$CA_DAYS" -out "$dir/ca.pem" \
    -subj "/CN=cluster CA $(date -u +%Y-%m-%dT%H:%M:%SZ)" \
    -addext "basicConstraints=critical,CA:TRUE,pathlen:0" \
    -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -addext "subjectKeyIdentifier=hash" 2> "$tmp/err" || { cat "$tmp/err" >&2; exit 1; }
  chmod 600 "$dir/ca.key"
  chmod 644 "$dir/ca.pem"
  echo "made the cluster CA $dir/ca.pem (key $dir/ca.key: keep it off the nodes)"
fi

for spec in "$@"; do
  name=${spec%%=*}
  sans=("$(san_entry "$name")")
  if [[ $spec == *=* ]]; then
    IFS=, read -r -a alts <<< "${spec#*=}"
    for a in "${alts[@]}"; do sans+=("$(san_entry "$a")"); done
  fi
  if [[ -e $dir/$name.pem || -e $dir/$name.key ]]; then
    echo "$name: $dir/$name.pem or $dir/$name.key exists, left as it is (remove both to reissue)"
    continue
  fi
  san=$(IFS=,; echo "${sans[*]}")
  cat > "$tmp/ext" <<EOF
basicConstraints=critical,CA:FALSE
keyUsage=critical,digitalSignature
extendedKeyUsage=serverAuth,clientAuth
subjectAltName=$san
subjectKeyIdentifier=hash
authorityKeyIdentifier=keyid
EOF
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$tmp/key" 2> "$tmp/err" ||
    { cat "$tmp/err" >&2; exit 1; }
  openssl req -new -key "$tmp/key" -subj "/CN=$name" -out "$tmp/csr" 2> "$tmp/err" ||
    { cat "$tmp/err" >&2; exit 1; }
  openssl x509 -req -in "$tmp/csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" -sha256 -days "$DAYS" \
    -set_serial "0x$(openssl rand -hex 16)" -extfile "$tmp/ext" -out "$tmp/pem" 2> "$tmp/err" ||
    { cat "$tmp/err" >&2; exit 1; }
  openssl verify -CAfile "$dir/ca.pem" "$tmp/pem" > /dev/null 2> "$tmp/err" ||
    { echo "$0: the new certificate of $name does not verify:" >&2; cat "$tmp/err" >&2; exit 1; }
  mv "$tmp/key" "$dir/$name.key"
  chmod 600 "$dir/$name.key"
  mv "$tmp/pem" "$dir/$name.pem"
  chmod 644 "$dir/$name.pem"
  echo "$name: $dir/$name.pem and $dir/$name.key ($san, $DAYS days)"
done
