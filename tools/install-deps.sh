#!/usr/bin/env bash
# Installs the Debian packages the build needs (only the missing ones), adds the arm64 architecture and
# unpacks the arm64 -dev packages into the cross build's sysroot. Idempotent; root or sudo.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
top=$(cd "$here/.." && pwd)
sysroot=${AG_ARM64_SYSROOT:-$top/build/sysroot-aarch64}
sudo=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: not root and no sudo: install these as root: $(grep -v '^#' "$here/deps/debian-packages.txt" | xargs)" >&2; exit 1; }
  sudo=sudo
fi
export DEBIAN_FRONTEND=noninteractive

packages() { grep -v -e '^#' -e '^[[:space:]]*$' "$1"; }
installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }

updated=0
apt_update() { if [ $updated = 0 ]; then echo "install-deps: apt-get update"; $sudo apt-get update -qq; updated=1; fi; }

missing=()
# provided(): a virtual package satisfied by another installed one (NodeSource's nodejs provides npm and
# conflicts with Debian's), so an npm already on PATH counts.
provided() { [ "$1" = npm ] && command -v npm >/dev/null; }
for p in $(packages "$here/deps/debian-packages.txt"); do installed "$p" || provided "$p" || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  apt_update
  echo "install-deps: installing ${missing[*]}"
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all $(packages "$here/deps/debian-packages.txt" | wc -l) Debian packages present"
fi

# The browser test's npm package (playwright-core, pinned; it drives Debian's chromium).
"$here/install-browser-test.sh" || echo "install-deps: the browser test's npm package is missing (the browser test will skip)" >&2
# The official MCAP readers the recording tests read their files back with (@mcap/core, @mcap/support; pinned).
"$here/install-mcap-reader.sh" || echo "install-deps: the MCAP readers are missing (the recording tests will fail: run tools/install-mcap-reader.sh)" >&2
# Foxglove's WebSocket client (@foxglove/ws-protocol, ws; pinned) the live-connection test connects with.
"$here/install-foxglove-ws-client.sh" || echo "install-deps: the Foxglove WebSocket client is missing (the live Foxglove test will fail: run tools/install-foxglove-ws-client.sh)" >&2

# The cross build: arm64 architecture for apt, then the arm64 -dev packages unpacked into a sysroot
# folder (several -dev packages are not co-installable with their amd64 twins, so they are not installed).
if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  echo "install-deps: adding the arm64 architecture"
  $sudo dpkg --add-architecture arm64
  updated=0
fi
want=$(packages "$here/deps/arm64-packages.txt" | sort | xargs)
stamp="$sysroot/.packages"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  echo "install-deps: arm64 sysroot up to date ($sysroot)"
  exit 0
fi
apt_update
dl=$(mktemp -d)
trap 'rm -rf "$dl"' EXIT
chmod 777 "$dl"
echo "install-deps: unpacking arm64 packages into $sysroot: $want"
# A failed download (a package missing for arm64, no network) must stop here, not leave an empty sysroot.
if ! (cd "$dl" && apt-get download -q $(for p in $want; do echo "$p:arm64"; done)) >"$dl/download.log" 2>&1; then
  grep -v "^W: Download is performed unsandboxed" "$dl/download.log" >&2 || true
  echo "install-deps: apt-get download of the arm64 packages failed (sysroot left as it was)" >&2
  exit 1
fi
grep -v -e "^W: Download is performed unsandboxed" -e "^Get:" "$dl/download.log" || true
rm -rf "$sysroot"
mkdir -p "$sysroot"
for deb in "$dl"/*.deb; do dpkg-deb -x "$deb" "$sysroot"; done
echo "$want" >"$stamp"
