#!/usr/bin/env bash
# Installs the browser test's one npm package (playwright-core, the version pinned in
# tests/browser/package.json and package-lock.json) into tests/browser/node_modules. It drives Debian's
# chromium; no browser is downloaded (--ignore-scripts). Idempotent: does nothing when the pinned
# version is already there. Needs node and npm (Debian: apt-get install nodejs npm).
set -euo pipefail
if [ "${1:-}" = "--help" ] || [ "${1:-}" = "-h" ]; then
  sed -n "2,5p" "$0" | sed "s/^# \{0,1\}//"
  exit 0
fi
here=$(cd "$(dirname "$0")" && pwd)
dir=$(cd "$here/../tests/browser" && pwd)
want=$(sed -n 's/.*"playwright-core": *"\([^"]*\)".*/\1/p' "$dir/package.json" | head -1)
have=$(sed -n 's/^ *"version": *"\([^"]*\)".*/\1/p' "$dir/node_modules/playwright-core/package.json" 2>/dev/null | head -1 || true)
if [ -n "$have" ] && [ "$have" = "$want" ]; then
  echo "install-browser-test: playwright-core $have present ($dir/node_modules)"
  exit 0
fi
command -v npm >/dev/null || { echo "install-browser-test: npm not found (apt-get install nodejs npm); the browser test will be skipped" >&2; exit 1; }
echo "install-browser-test: npm ci playwright-core $want into $dir/node_modules"
(cd "$dir" && npm ci --no-audit --no-fund --ignore-scripts --loglevel=error)
echo "install-browser-test: done ($(sed -n 's/^ *"version": *"\([^"]*\)".*/\1/p' "$dir/node_modules/playwright-core/package.json" | head -1))"
