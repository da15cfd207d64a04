#!/usr/bin/env bash
# Builds deploy/Dockerfile with podman and checks the gRPC health of the
# running image. Opt-in: set DYNSOLID_CONTAINER_TEST=1 (it installs podman
# and debootstrap, makes a bookworm root from Debian's mirror, imports it as
# the base since no image registry is reachable, and compiles the project in
# the build stage: tens of minutes on two cores). Exit 77 = skipped.
set -euo pipefail
SRC=$1
if [ "${DYNSOLID_CONTAINER_TEST:-0}" != 1 ]; then
  echo "SKIPPED: the container image test is opt-in (DYNSOLID_CONTAINER_TEST=1): it builds a"
  echo "Debian root with debootstrap and the whole project inside podman, tens of minutes here."
  exit 77
fi
export DEBIAN_FRONTEND=noninteractive
if ! command -v podman >/dev/null || ! command -v debootstrap >/dev/null; then
  apt-get update -qq && apt-get install -y -qq --no-install-recommends podman debootstrap >/dev/null
fi
if ! podman info >/dev/null 2>&1; then
  echo "SKIPPED: podman is installed but cannot run here: $(podman info 2>&1 | tail -1)"
  exit 77
fi
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
if ! podman image exists dynsolid-base:bookworm; then
  MIRROR=$(sed -n 's/^URIs: //p' /etc/apt/sources.list.d/debian.sources 2>/dev/null | head -1)
  debootstrap --variant=minbase bookworm "$WORK/root" "${MIRROR:-http://deb.debian.org/debian}" >/dev/null
  tar -C "$WORK/root" -c . | podman import - dynsolid-base:bookworm >/dev/null
fi
# Can a container run here at all? (On the VM this was written on it
# cannot: crun refuses cgroup v1/v2 hybrid mode, and runc cannot set
# RLIMIT_NPROC: "operation not permitted".)
if ! out=$(podman run --rm dynsolid-base:bookworm true 2>&1); then
  echo "SKIPPED: podman cannot run a container on this machine: $(echo "$out" | tail -1)"
  exit 77
fi
podman build -q --build-arg BASE=dynsolid-base:bookworm -f "$SRC/deploy/Dockerfile" -t dynsolid-server:test "$SRC"
CID=$(podman run -d -p 127.0.0.1:0:50051 dynsolid-server:test --health_listen 0.0.0.0:50052)
trap 'podman rm -f "$CID" >/dev/null; rm -rf "$WORK"' EXIT
PORT=$(podman port "$CID" 50051 | sed 's/.*://')
for _ in $(seq 100); do
  if podman exec "$CID" /usr/local/bin/dynsolid-client --server 127.0.0.1:50051 list >/dev/null 2>&1; then
    echo "the image serves dynsolid.Sessions (host port $PORT)"
    exit 0
  fi
  sleep 0.2
done
echo "FAIL: the container did not answer; its log:"
podman logs "$CID" | tail -20
exit 1
