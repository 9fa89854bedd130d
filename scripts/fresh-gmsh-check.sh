#!/usr/bin/env bash
# Checks the Gmsh install step of scripts/test-all.sh on a fresh Debian 12 (a debootstrap
# minbase chroot: no Python, no pip, no X/GL libraries), then runs `host mesh` there on a
# committed test surface. Needs root and debootstrap; the chroot lives in $1 (default
# /tmp/fresh-gmsh, about 700 MB once Gmsh is in). The host binary is the checked build
# (`cargo build --profile checked -p host`).
#
#     sudo bash scripts/fresh-gmsh-check.sh [DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
root=${1:-/tmp/fresh-gmsh}
host_bin=target/checked/host
[ -x "$host_bin" ] || { echo "error: build $host_bin first (cargo build --profile checked -p host)" >&2; exit 1; }
if [ ! -x "$root/usr/bin/apt-get" ]; then
    debootstrap --variant=minbase bookworm "$root" http://deb.debian.org/debian
fi
cp /etc/resolv.conf "$root/etc/resolv.conf"
# The machine's own certificate authorities (a proxy's, where there is one), as a fresh
# machine of this kind has them.
if compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
    mkdir -p "$root/usr/local/share/ca-certificates"
    cp /usr/local/share/ca-certificates/*.crt "$root/usr/local/share/ca-certificates/"
fi
# test-all.sh's own lines: its apt-get helper and its Gmsh step, verbatim.
{
    echo 'set -euo pipefail'
    printf '%s\n' 'step() { printf "\n== %s\n" "$*"; }'
    sed -n '/^removed=()/,/^trap report_removed EXIT/p;/^apt_install() {/,/^}/p' scripts/test-all.sh
    sed -n '/^step "Gmsh for host mesh/,/^python3 -c .import gmsh; print/p' scripts/test-all.sh
} >"$root/root/gmsh-install.sh"
cp "$host_bin" "$root/root/host"
cp host/tests/data/surfaces/organ_cm.obj "$root/root/"
run() {
    chroot "$root" env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
        HOME=/root PIP_CERT=/etc/ssl/certs/ca-certificates.crt bash -c "$1"
}
# (apt's ca-certificates, which python3-pip brings, adds the copied authorities when it installs.)
run 'bash /root/gmsh-install.sh'
run 'cd /root && ./host mesh organ_cm.obj -o organ.msh'
echo "fresh-gmsh-check: Gmsh installed by test-all.sh's step and host mesh ran in $root"
