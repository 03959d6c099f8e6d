#!/usr/bin/env bash
# Installs the Foxglove WebSocket client our live-connection test uses (@foxglove/ws-protocol, and ws as
# its WebSocket since Node 18 has none built in: the versions pinned in tests/foxglove_ws_client/
# package.json and package-lock.json) into tests/foxglove_ws_client/node_modules. Idempotent: does
# nothing when the pinned versions are there. Needs node and npm (Debian: apt-get install nodejs npm).
set -euo pipefail
if [ "${1:-}" = "--help" ] || [ "${1:-}" = "-h" ]; then
  sed -n "2,5p" "$0" | sed "s/^# \{0,1\}//"
  exit 0
fi
here=$(cd "$(dirname "$0")" && pwd)
dir=$(cd "$here/../tests/foxglove_ws_client" && pwd)
version() { sed -n 's/^ *"version": *"\([^"]*\)".*/\1/p' "$dir/node_modules/$1/package.json" 2>/dev/null | head -1 || true; }
want() { sed -n "s|.*\"$1\": *\"\\([^\"]*\\)\".*|\\1|p" "$dir/package.json" | head -1; }
present=1
for p in @foxglove/ws-protocol ws; do
  [ "$(version "$p")" = "$(want "$p")" ] || present=0
done
if [ "$present" = 1 ]; then
  echo "install-foxglove-ws-client: @foxglove/ws-protocol $(version @foxglove/ws-protocol), ws $(version ws) present ($dir/node_modules)"
  exit 0
fi
command -v npm >/dev/null || { echo "install-foxglove-ws-client: npm not found (apt-get install nodejs npm); the live Foxglove test cannot connect" >&2; exit 1; }
echo "install-foxglove-ws-client: npm ci into $dir/node_modules"
(cd "$dir" && npm ci --no-audit --no-fund --ignore-scripts --loglevel=error)
echo "install-foxglove-ws-client: done (@foxglove/ws-protocol $(version @foxglove/ws-protocol), ws $(version ws))"
