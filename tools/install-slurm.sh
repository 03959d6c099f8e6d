#!/usr/bin/env bash
# Installs Debian's Slurm (controller, node daemon, client commands) and MUNGE for `make test-slurm`
# only (not part of `make deps`): the test starts its own single-node cluster and stops it again.
# Idempotent; root or sudo. Daemons the packages' scripts may start are stopped again (the test runs
# its own munged, slurmctld and slurmd on private sockets, ports and spool folders).
set -euo pipefail
packages=(slurmctld slurmd slurm-client munge)
sudo=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || { echo "install-slurm: not root and no sudo: install these as root: ${packages[*]}" >&2; exit 1; }
  sudo=sudo
fi
export DEBIAN_FRONTEND=noninteractive
installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
missing=()
for p in "${packages[@]}"; do installed "$p" || missing+=("$p"); done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-slurm: ${packages[*]} present (slurm $(dpkg-query -W -f='${Version}' slurmctld))"
  exit 0
fi
echo "install-slurm: apt-get update"
$sudo apt-get update -qq
echo "install-slurm: installing ${missing[*]}"
# No service starts at install time (a container has no init; a machine keeps its own Slurm untouched).
policy=/usr/sbin/policy-rc.d
added_policy=0
if [ ! -e "$policy" ]; then
  printf '#!/bin/sh\nexit 101\n' | $sudo tee "$policy" >/dev/null
  $sudo chmod 755 "$policy"
  added_policy=1
fi
status=0
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" || status=$?
if [ $added_policy = 1 ]; then $sudo rm -f "$policy"; fi
[ $status = 0 ] || { echo "install-slurm: apt-get install ${missing[*]} failed (exit $status)" >&2; exit $status; }
echo "install-slurm: slurm $(dpkg-query -W -f='${Version}' slurmctld) installed"
