#!/bin/sh
# Build the cbdi image with Podman or Docker (whichever runs), with no registry needed.
#
#   tools/image.sh            (or: make image)
#
# 1. The base: CBDI_BASE_IMAGE if it exists already (default localhost/cbdi-base:bookworm).
#    Else it is made here: debootstrap a minimal Debian bookworm with Python 3.11 (venv)
#    from the Debian mirror apt uses, trimmed, then `podman import` / `docker import`.
#    The root file system is kept as a tarball in CBDI_IMAGE_CACHE (default
#    ~/.cache/cbdi), so a lost base is imported again in seconds. A base from a registry
#    works too: CBDI_BASE_IMAGE=python:3.11-slim tools/image.sh.
# 2. The planner's compiled core (Rust), built with the host's cargo (services/planner/core).
# 3. The image (CBDI_IMAGE, default localhost/cbdi:latest) from the Dockerfile on that base.
#    When the host has them, its CA bundle (PIP_CERT, REQUESTS_CA_BUNDLE, SSL_CERT_FILE or
#    /etc/ssl/certs/ca-certificates.crt), its pip configuration (PIP_CONFIG_FILE,
#    /etc/pip.conf, ~/.config/pip/pip.conf, ~/.pip/pip.conf) and PIP_INDEX_URL,
#    PIP_EXTRA_INDEX_URL, PIP_TRUSTED_HOST go to the build stage (tools/image/build-env),
#    so pip works behind a machine's own certificate authority or package index; the
#    final image carries none of them.
#
# Environment: CBDI_ENGINE (podman|docker, default: the first that runs), CBDI_IMAGE,
# CBDI_BASE_IMAGE, CBDI_IMAGE_CACHE, DEBIAN_MIRROR, CBDI_REBUILD_BASE=1 (make the base anew).
set -eu

REPO=$(cd "$(dirname "$0")/.." && pwd)
IMAGE=${CBDI_IMAGE:-localhost/cbdi:latest}
BASE=${CBDI_BASE_IMAGE:-localhost/cbdi-base:bookworm}
CACHE=${CBDI_IMAGE_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/cbdi}
STAGE=$REPO/tools/image/build-env

say() { echo "image: $*" >&2; }
die() { say "$*"; exit 1; }

engine() {
  if [ -n "${CBDI_ENGINE:-}" ]; then echo "$CBDI_ENGINE"; return; fi
  for e in podman docker; do
    if command -v "$e" >/dev/null 2>&1 && "$e" info >/dev/null 2>&1; then echo "$e"; return; fi
  done
  die "neither podman nor docker can run here (Debian: apt-get install podman)"
}

mirror() {
  # The Debian mirror apt uses (deb822 or one-line sources), else deb.debian.org.
  if [ -n "${DEBIAN_MIRROR:-}" ]; then echo "$DEBIAN_MIRROR"; return; fi
  found=$(cat /etc/apt/sources.list.d/*.sources 2>/dev/null \
    | awk '$1 == "URIs:" && $2 !~ /security/ { print $2; exit }')
  [ -n "$found" ] || found=$(cat /etc/apt/sources.list 2>/dev/null \
    | awk '$1 == "deb" && $0 !~ /security/ { for (i = 2; i <= NF; i++) if ($i ~ /^https?:/) { print $i; exit } }')
  echo "${found:-http://deb.debian.org/debian}"
}

make_rootfs() {
  # A minimal bookworm with python3-venv (pip comes with ensurepip), trimmed of docs,
  # locales and apt's lists: about 110 MB.
  command -v debootstrap >/dev/null 2>&1 || die "debootstrap is missing (apt-get install debootstrap)"
  root=$(mktemp -d "${TMPDIR:-/var/tmp}/cbdi-rootfs.XXXXXX")
  trap 'rm -rf "$root"' EXIT
  say "debootstrap bookworm from $(mirror) (a few minutes, once)"
  debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates \
    bookworm "$root" "$(mirror)" >"$root.log" 2>&1 || { tail -20 "$root.log" >&2; die "debootstrap failed"; }
  rm -f "$root.log"
  rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/* \
    "$root"/usr/share/doc/* "$root"/usr/share/man/* "$root"/usr/share/info/* \
    "$root"/usr/share/locale/* "$root"/var/log/*.log "$root"/var/cache/debconf/*-old
  mkdir -p "$CACHE"
  tar -C "$root" --numeric-owner -cf "$CACHE/base-bookworm.tar.part" .
  mv "$CACHE/base-bookworm.tar.part" "$CACHE/base-bookworm.tar"
  rm -rf "$root"
  trap - EXIT
}

base() {
  e=$1
  if [ -z "${CBDI_REBUILD_BASE:-}" ] && "$e" image inspect "$BASE" >/dev/null 2>&1; then
    say "base $BASE exists"; return
  fi
  case "$BASE" in
    localhost/cbdi-base:*) ;;
    *) say "base $BASE is not made here: $e pulls it during the build"; return ;;
  esac
  if [ -n "${CBDI_REBUILD_BASE:-}" ] || [ ! -f "$CACHE/base-bookworm.tar" ]; then make_rootfs; fi
  say "importing $CACHE/base-bookworm.tar as $BASE"
  "$e" import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LANG=C.UTF-8' --change 'CMD ["/bin/bash"]' \
    "$CACHE/base-bookworm.tar" "$BASE" >/dev/null
}

stage() {
  # Copy the host's CA bundle and pip settings into the build stage's directory.
  unstage
  for f in "${PIP_CERT:-}" "${REQUESTS_CA_BUNDLE:-}" "${SSL_CERT_FILE:-}" /etc/ssl/certs/ca-certificates.crt; do
    if [ -n "$f" ] && [ -f "$f" ]; then cp "$f" "$STAGE/ca.crt"; say "CA bundle from $f"; break; fi
  done
  for f in "${PIP_CONFIG_FILE:-}" /etc/pip.conf "$HOME/.config/pip/pip.conf" "$HOME/.pip/pip.conf"; do
    if [ -n "$f" ] && [ -f "$f" ]; then cp "$f" "$STAGE/pip.conf"; say "pip configuration from $f"; break; fi
  done
  : >"$STAGE/pip.env"
  for v in PIP_INDEX_URL PIP_EXTRA_INDEX_URL PIP_TRUSTED_HOST; do
    eval "value=\${$v:-}"
    # shellcheck disable=SC2154 # set by the eval
    if [ -n "$value" ]; then printf "export %s='%s'\n" "$v" "$value" >>"$STAGE/pip.env"; say "$v set"; fi
  done
}

core() {
  # The planner's compiled core, built here with the host's cargo (the base has no Rust),
  # its crates pinned by Cargo.lock, into a cache kept between builds; the build stage
  # puts it in the image's venv. An abi3 module: any Python 3.11 of the same libc loads it.
  cargo=$(command -v cargo 2>/dev/null || ls "$HOME/.cargo/bin/cargo" 2>/dev/null || true)
  [ -n "$cargo" ] || die "the planner's compiled core needs Rust's cargo: install Rust (https://rustup.rs)"
  say "compiled core: cargo build (cached in $CACHE/cargo-target)"
  "$cargo" build -q --release --locked --manifest-path "$REPO/services/planner/core/Cargo.toml" \
    --target-dir "$CACHE/cargo-target" || die "the compiled core did not build"
  cp "$CACHE/cargo-target/release/libcbdi_planner_core.so" "$STAGE/cbdi_planner_core.abi3.so"
}

unstage() { rm -f "$STAGE/ca.crt" "$STAGE/pip.conf" "$STAGE/pip.env" "$STAGE/cbdi_planner_core.abi3.so"; }

main() {
  e=$(engine)
  say "engine $e"
  base "$e"
  stage
  trap unstage EXIT
  core
  start=$(date +%s)
  "$e" build --build-arg "BASE_IMAGE=$BASE" -t "$IMAGE" -f "$REPO/Dockerfile" "$REPO"
  unstage
  trap - EXIT
  size=$("$e" image inspect "$IMAGE" --format '{{.Size}}')
  say "built $IMAGE on $BASE in $(($(date +%s) - start)) s: $((size / 1000000)) MB"
}

main "$@"
