#!/usr/bin/env bash
# Installs the Debian 12 packages Filigree builds and tests with; with
# --container, those that build and run the container image instead (podman).
# Idempotent: only packages that are not installed yet are fetched, and apt's
# package lists are refreshed only when something is missing.
set -euo pipefail

PACKAGES=(
  cmake ninja-build g++ make pkg-config ccache python3
  libeigen3-dev libopenmesh-dev libtinygltf-dev libdraco-dev libsuitesparse-dev
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libxxhash-dev libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev libspdlog-dev
  libboost-dev libhiredis-dev libssl-dev
  redis-server nginx
  chromium fonts-liberation
  python3-numpy python3-pytest python3-venv python3-setuptools python3-pip
  blender xvfb xauth clang
)

container=false
if [ "${1:-}" = "--container" ]; then
  container=true
  PACKAGES=(podman runc debootstrap curl ca-certificates uidmap)
fi

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

# tests/node_client: node >= 18 and npm. Keep any node already there (NodeSource's
# bundles npm and conflicts with Debian's npm package); else Debian's nodejs + npm.
if ! $container && { ! command -v node >/dev/null || ! command -v npm >/dev/null; }; then
  missing+=(nodejs npm)
fi

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
