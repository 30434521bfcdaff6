#!/usr/bin/env bash
# Builds the Filigree server image with podman (what `make image` runs):
#
#   1. the base image, once: if $FILIGREE_BASE_IMAGE (localhost/filigree-base:bookworm)
#      is missing, a minimal Debian 12 root file system from debootstrap,
#      imported with `podman import` (no container registry needed);
#   2. docker/Dockerfile from the repository root, tagged $FILIGREE_IMAGE
#      (localhost/filigree:latest).
#
# Idempotent: a second run reuses the base image and podman's layer cache.
# Needs root (debootstrap, and podman's storage under /var/lib/containers),
# podman, runc and debootstrap; network access to the Debian mirror and the npm
# registry (the build's RUN steps use the host's network).
#
# Environment:
#   FILIGREE_IMAGE        image to build             (localhost/filigree:latest)
#   FILIGREE_BASE_IMAGE   base image, made if absent (localhost/filigree-base:bookworm)
#   FILIGREE_BASE         use this base instead, e.g. docker.io/library/debian:bookworm
#                         where a registry is reachable (no debootstrap then)
#   DEBIAN_MIRROR         debootstrap and apt mirror (http://deb.debian.org/debian)
#   DEBIAN_SECURITY_MIRROR                           (http://deb.debian.org/debian-security)
#   FILIGREE_BUILD_CA     PEM bundle npm should trust inside the build (default: the
#                         host's npm cafile, else /etc/ssl/certs/ca-certificates.crt);
#                         needed behind a TLS-intercepting proxy, harmless elsewhere
#   CONTAINERS_CONF       podman configuration (docker/podman/containers.conf)
#   PODMAN_BUILD_ARGS     extra arguments for `podman build` (e.g. --no-cache)
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/.." && pwd)
fail() { echo "build-image: $*" >&2; exit 1; }
log() { echo "build-image: $*"; }

IMAGE=${FILIGREE_IMAGE:-localhost/filigree:latest}
BASE_IMAGE=${FILIGREE_BASE_IMAGE:-localhost/filigree-base:bookworm}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
SECURITY_MIRROR=${DEBIAN_SECURITY_MIRROR:-http://deb.debian.org/debian-security}
export CONTAINERS_CONF=${CONTAINERS_CONF:-$here/podman/containers.conf}

command -v podman >/dev/null || fail "podman not found (Debian: apt-get install podman runc)"
[ -f "$CONTAINERS_CONF" ] || fail "CONTAINERS_CONF=$CONTAINERS_CONF does not exist"

# ---------------------------------------------------------------- base image
make_base() {
  [ "$(id -u)" -eq 0 ] || fail "making the base image needs root (debootstrap)"
  command -v debootstrap >/dev/null || fail "debootstrap not found (Debian: apt-get install debootstrap)"
  local work rootfs
  work=$(mktemp -d /var/tmp/filigree-base.XXXXXX)
  rootfs=$work/rootfs
  # debootstrap mounts /proc, /sys (and in a container binds /dev) inside the
  # target while it runs: unmount whatever is left before deleting anything,
  # and never cross into another file system.
  cleanup_base() {
    local m
    for m in $(awk -v p="$rootfs/" 'index($2, p) == 1 { print $2 }' /proc/mounts | sort -r); do
      umount -l "$m" 2>/dev/null || true
    done
    rm -rf --one-file-system "$work"
  }
  trap cleanup_base EXIT

  log "debootstrap --variant=minbase bookworm from $MIRROR (once)"
  debootstrap --variant=minbase bookworm "$rootfs" "$MIRROR" >"$work/debootstrap.log" 2>&1 ||
    { tail -n 30 "$work/debootstrap.log" >&2; fail "debootstrap failed (log above)"; }

  # Sources as in Debian's own bookworm image: main, updates and security.
  rm -f "$rootfs/etc/apt/sources.list"
  cat >"$rootfs/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $MIRROR
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: $SECURITY_MIRROR
Suites: bookworm-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
  # Container conventions of Debian's image: no recommends, no apt caches left behind.
  cat >"$rootfs/etc/apt/apt.conf.d/90filigree-container" <<'EOF'
APT::Install-Recommends "false";
APT::Install-Suggests "false";
DPkg::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
EOF
  # Slim, as Debian's bookworm-slim: no documentation, manuals or translations
  # (copyright files stay), now or from packages installed later.
  cat >"$rootfs/etc/dpkg/dpkg.cfg.d/90filigree-slim" <<'EOF'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/info/*
path-exclude /usr/share/man/*
path-exclude /usr/share/locale/*
path-exclude /usr/share/groff/*
path-exclude /usr/share/lintian/*
EOF
  find "$rootfs/usr/share/doc" -mindepth 1 -not -name copyright -not -type d -delete
  find "$rootfs/usr/share/doc" -mindepth 1 -type d -empty -delete
  rm -rf "$rootfs"/usr/share/info/* "$rootfs"/usr/share/man/* "$rootfs"/usr/share/locale/* \
    "$rootfs"/usr/share/groff/* "$rootfs"/usr/share/lintian/*
  rm -rf "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/* "$rootfs"/var/log/* "$rootfs"/tmp/*
  : >"$rootfs/etc/hostname"

  log "podman import -> $BASE_IMAGE"
  tar --numeric-owner -C "$rootfs" -c . |
    podman import --change 'CMD ["/bin/bash"]' --change 'ENV LANG=C.UTF-8' - "$BASE_IMAGE" >/dev/null
  cleanup_base
  trap - EXIT
}

if [ -n "${FILIGREE_BASE:-}" ]; then
  BASE_IMAGE=$FILIGREE_BASE
  log "base image $BASE_IMAGE (FILIGREE_BASE)"
elif podman image exists "$BASE_IMAGE"; then
  log "base image $BASE_IMAGE present"
else
  make_base
fi

# ---------------------------------------------------------------- image
# CA bundle for npm inside the build, given as a build secret (not stored in the image).
ca=${FILIGREE_BUILD_CA:-}
if [ -z "$ca" ] && command -v npm >/dev/null; then
  ca=$(npm config get cafile 2>/dev/null || true)
  case "$ca" in null | undefined) ca="" ;; esac
fi
if [ -z "$ca" ] && [ -f /etc/ssl/certs/ca-certificates.crt ]; then ca=/etc/ssl/certs/ca-certificates.crt; fi
secret_args=()
if [ -n "$ca" ]; then
  [ -r "$ca" ] || fail "FILIGREE_BUILD_CA=$ca is not readable"
  secret_args=(--secret "id=build_ca,src=$ca")
fi

log "podman build -> $IMAGE (base $BASE_IMAGE)"
start=$(date +%s)
# --format docker keeps the HEALTHCHECK (the OCI format has none);
# --network=host: the RUN steps reach the Debian mirror and the npm registry as
# the host does (same DNS, same routes), without a container network to set up.
# shellcheck disable=SC2086
podman build --network=host --format docker \
  -f "$here/Dockerfile" \
  --build-arg "BASE=$BASE_IMAGE" \
  "${secret_args[@]}" \
  ${PODMAN_BUILD_ARGS:-} \
  -t "$IMAGE" "$root"
elapsed=$(($(date +%s) - start))

size=$(podman image inspect --format '{{.Size}}' "$IMAGE")
log "built $IMAGE in ${elapsed}s"
log "image size: $((size / 1024 / 1024)) MiB ($size bytes)"
