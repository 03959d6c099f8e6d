#!/bin/sh
# The role binaries' install split (cmake/Dbgsym.cmake), as make package uses it: the role's component
# installs the binary stripped, with a .gnu_debuglink; <role>_dbgsym installs its symbols at
# usr/lib/debug/.build-id/xx/yyyy.debug for the binary's own build id, and a doc link to the package.
# usage: check_split.sh BUILD_DIR ROLE READELF
set -eu
build=$1 role=$2 readelf=$3
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
# DESTDIR: the unit and the config install to absolute /lib and /etc paths, which must land in $out too.
DESTDIR=$out cmake --install "$build" --component "$role" --prefix /usr >/dev/null
DESTDIR=$out cmake --install "$build" --component "${role}_dbgsym" --prefix /usr >/dev/null
[ -f "$out/etc/airground/$role.yaml" ] || fail "the config did not install under DESTDIR"
bin=$out/usr/bin/airground-$role
[ -x "$bin" ] || fail "$bin not installed"
"$readelf" -S "$bin" | grep -q '\.symtab' && fail "$bin still has a symbol table (not stripped)"
"$readelf" -S "$bin" | grep -q '\.debug_info' && fail "$bin still has debug info"
"$readelf" -S "$bin" | grep -q '\.gnu_debuglink' || fail "$bin has no .gnu_debuglink"
id=$("$readelf" -n "$bin" | sed -n 's/.*Build ID: \([0-9a-f]*\).*/\1/p')
[ -n "$id" ] || fail "$bin has no build id"
dbg=$out/usr/lib/debug/.build-id/$(echo "$id" | cut -c1-2)/$(echo "$id" | cut -c3-).debug
[ -f "$dbg" ] || fail "no symbols at ${dbg#$out} for build id $id"
"$readelf" -S "$dbg" | grep -q '\.debug_info' || fail "$dbg holds no debug info"
[ "$("$readelf" -n "$dbg" | sed -n 's/.*Build ID: \([0-9a-f]*\).*/\1/p')" = "$id" ] || fail "$dbg is for another build id"
[ "$(readlink "$out/usr/share/doc/airground-$role-dbgsym")" = "airground-$role" ] || fail "no doc link in the dbgsym component"
[ "$(stat -c %s "$bin")" -lt "$(stat -c %s "$build/firmware_host/airground-$role")" ] || fail "the installed binary is not smaller"
echo "airground-$role: stripped $(stat -c %s "$bin") B (build tree $(stat -c %s "$build/firmware_host/airground-$role") B), symbols $(stat -c %s "$dbg") B at ${dbg#$out}"
