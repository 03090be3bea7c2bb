#!/usr/bin/env bash
# Makes a self-signed certificate for a node's HTTPS and WSS, for local use and tests:
#   scripts/tls-cert.sh DIR [NAME ...]
# writes DIR/node.crt and DIR/node.key (mode 600): an EC P-256 key and a certificate valid for
# 825 days for localhost, 127.0.0.1, ::1 and every NAME (a host name or an IP address). Then
#   tessera serve --tessera.tls-cert=DIR/node.crt --tessera.tls-key=DIR/node.key
# serves https:// and wss:// only. A browser warns about a self-signed certificate until it is
# trusted (import DIR/node.crt) or started with --ignore-certificate-errors (tests only); for a
# public node use a certificate from a CA (e.g. Let's Encrypt) instead. Refuses to overwrite.
set -euo pipefail
if [[ $# -lt 1 || $1 == -h || $1 == --help ]]; then
  sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'
  exit $(( $# < 1 ? 2 : 0 ))
fi
dir=$1; shift
command -v openssl >/dev/null || { echo "tls-cert.sh: openssl is missing (apt-get install openssl)" >&2; exit 1; }
mkdir -p "$dir"
crt=$dir/node.crt key=$dir/node.key
for f in "$crt" "$key"; do
  [[ -e $f ]] && { echo "tls-cert.sh: $f exists; not overwritten (remove it first)" >&2; exit 1; }
done
san="DNS:localhost,IP:127.0.0.1,IP:::1"
for n in "$@"; do
  if [[ $n =~ ^[0-9.]+$ || $n == *:* ]]; then san+=",IP:$n"; else san+=",DNS:$n"; fi
done
umask 077
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 825 \
  -subj "/CN=${1:-localhost}/O=Tessera node (self-signed)" -addext "subjectAltName=$san" \
  -addext "keyUsage=critical,digitalSignature" -addext "extendedKeyUsage=serverAuth" \
  -keyout "$key" -out "$crt" 2>/dev/null
chmod 600 "$key"
chmod 644 "$crt"
echo "$crt"
echo "$key"
