#!/bin/sh
# Certificates for a secured idmesh deployment ([security] in the topology):
# a CA, and for every process or client named, a key and a certificate whose
# common name is that name, signed by the CA. The subject alternative names
# name loopback; on a LAN put each host's address there instead.
#
# usage: sh deploy/examples/make-certs.sh DIR NAME...
#   e.g. sh deploy/examples/make-certs.sh deploy/examples/certs \
#          coordinator sensor-0 leader-0 leader-1 operator
# Needs openssl. Keep DIR/ca.key off the hosts.
set -eu
if [ "$#" -lt 2 ]; then
    echo "usage: $0 DIR NAME..." >&2
    exit 2
fi
dir=$1
shift
mkdir -p "$dir"
cd "$dir"
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 365 \
    -subj "/CN=idmesh CA" -keyout ca.key -out ca.pem 2>/dev/null
printf "subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth,clientAuth\n" > ext
for name in "$@"; do
    openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes \
        -subj "/CN=$name" -keyout "$name.key" -out "$name.csr" 2>/dev/null
    openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial \
        -days 365 -extfile ext -out "$name.pem" 2>/dev/null
done
rm -f ext ./*.csr ca.srl
echo "$dir: ca.pem and a key and certificate for each of: $*"
