# Sourced by the Dockerfile's build stage before pip runs. tools/image.sh stages the
# host's CA bundle (ca.crt), pip configuration (pip.conf) and index settings (pip.env)
# beside this file when the host has them; a plain `docker build` finds none of them.
# Only the build stage sees this directory: nothing of it reaches the final image.
d=/tmp/build-env
if [ -f "$d/ca.crt" ]; then
  export PIP_CERT="$d/ca.crt" SSL_CERT_FILE="$d/ca.crt" REQUESTS_CA_BUNDLE="$d/ca.crt"
fi
if [ -f "$d/pip.conf" ]; then
  export PIP_CONFIG_FILE="$d/pip.conf"
fi
if [ -f "$d/pip.env" ]; then
  . "$d/pip.env"
fi
