#!/usr/bin/env bash
# Installs what the browser viewer (clients/web) needs to run and be tested:
# Node.js and npm (Debian's, when the machine has none), Debian's chromium
# (the end-to-end tests drive it with playwright-core; no browser download),
# and clients/web's npm packages exactly as the committed lock file pins
# them (npm ci). Idempotent: does nothing when all is in place.
set -euo pipefail
cd "$(dirname "$0")/.."

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

missing=()
if ! command -v node >/dev/null 2>&1; then missing+=(nodejs); fi
if ! command -v npm >/dev/null 2>&1; then missing+=(npm); fi
if ! dpkg-query -W -f='${Status}' chromium 2>/dev/null | grep -q "install ok installed"; then
  missing+=(chromium)
fi
if [ "${#missing[@]}" -gt 0 ]; then
  echo "setup_web: installing ${missing[*]}" >&2
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

major=$(node -p 'process.versions.node.split(".")[0]')
if [ "$major" -lt 18 ]; then
  echo "setup_web: Node.js $(node --version) is too old; the viewer needs 18 or newer" >&2
  exit 1
fi

# npm ci only when the lock file changed since the last install (also for
# tests/io/gltf, the glTF validator of the io tests).
for WEB in clients/web tests/io/gltf; do
STAMP=$WEB/node_modules/.dynsolid-lock.sha256
want=$(sha256sum "$WEB/package-lock.json" | cut -d' ' -f1)
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$want" ]; then
  echo "setup_web: npm ci in $WEB" >&2
  (cd "$WEB" && npm ci --no-audit --no-fund --loglevel=error)
  echo "$want" > "$STAMP"
fi
done
