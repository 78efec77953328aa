#!/usr/bin/env bash
# Create or remove virtual CAN interfaces vcan0 .. vcan<N-1> (default N = 1).
#   tools/vcan.sh up [N]     load the vcan module and bring the interfaces up
#   tools/vcan.sh down [N]   remove them
# Needs root (or CAP_NET_ADMIN) and a kernel with CONFIG_CAN_VCAN.
set -euo pipefail

usage() {
    echo "usage: $(basename "$0") up|down [N]   (create/remove vcan0..vcanN-1, default N=1)" >&2
    exit 2
}

die() {
    echo "vcan.sh: error: $*" >&2
    exit 1
}

[[ $# -ge 1 && $# -le 2 ]] || usage
action=$1
count=${2:-1}
[[ "$count" =~ ^[0-9]+$ && "$count" -ge 1 && "$count" -le 64 ]] || die "N must be a whole number from 1 to 64, got '$count'"
case "$action" in
    up|down) ;;
    -h|--help) sed -n '2,5p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) usage ;;
esac

[[ $(id -u) -eq 0 ]] || die "must run as root (try: sudo $0 $*)"
command -v ip >/dev/null || die "the 'ip' command (iproute2) is not installed"

if [[ "$action" == up ]]; then
    if [[ ! -d /sys/module/vcan ]]; then
        command -v modprobe >/dev/null || die "modprobe (kmod) is not installed"
        modprobe vcan 2>/dev/null || die "this kernel has no vcan support (modprobe vcan failed: CONFIG_CAN_VCAN missing?)"
    fi
    for ((i = 0; i < count; i++)); do
        dev=vcan$i
        if [[ ! -e /sys/class/net/$dev ]]; then
            ip link add dev "$dev" type vcan || die "could not create $dev"
        fi
        ip link set up "$dev" || die "could not bring $dev up"
        echo "$dev up"
    done
else
    for ((i = 0; i < count; i++)); do
        dev=vcan$i
        if [[ -e /sys/class/net/$dev ]]; then
            ip link delete "$dev" || die "could not remove $dev"
            echo "$dev removed"
        else
            echo "$dev not present"
        fi
    done
fi
