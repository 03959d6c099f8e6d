#!/usr/bin/env bash
# Installs the MCAP readers our tests read recordings back with (@mcap/core, @mcap/support, @foxglove/crc:
# the versions pinned in tests/mcap_reader/package.json and package-lock.json) into
# tests/mcap_reader/node_modules. Idempotent: does nothing when the pinned versions are there. Needs node
# and npm (Debian: apt-get install nodejs npm).
set -euo pipefail
if [ "${1:-}" = "--help" ] || [ "${1:-}" = "-h" ]; then
  sed -n "2,5p" "$0" | sed "s/^# \{0,1\}//"
  exit 0
fi
here=$(cd "$(dirname "$0")" && pwd)
dir=$(cd "$here/../tests/mcap_reader" && pwd)
version() { sed -n 's/^ *"version": *"\([^"]*\)".*/\1/p' "$dir/node_modules/$1/package.json" 2>/dev/null | head -1 || true; }
want() { sed -n "s|.*\"$1\": *\"\\([^\"]*\\)\".*|\\1|p" "$dir/package.json" | head -1; }
present=1
for p in @mcap/core @mcap/support @foxglove/crc; do
  [ "$(version "$p")" = "$(want "$p")" ] || present=0
done
if [ "$present" = 1 ]; then
  echo "install-mcap-reader: @mcap/core $(version @mcap/core), @mcap/support $(version @mcap/support) present ($dir/node_modules)"
  exit 0
fi
command -v npm >/dev/null || { echo "install-mcap-reader: npm not found (apt-get install nodejs npm); the MCAP tests cannot read their files back" >&2; exit 1; }
echo "install-mcap-reader: npm ci into $dir/node_modules"
(cd "$dir" && npm ci --no-audit --no-fund --ignore-scripts --loglevel=error)
echo "install-mcap-reader: done (@mcap/core $(version @mcap/core), @mcap/support $(version @mcap/support))"
