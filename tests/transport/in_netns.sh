#!/bin/sh
# Runs a command inside a private network namespace whose loopback carries
# multicast (STACK.md): LCM and DDS tests send nothing off this machine.
# Exit 77 (ctest: skipped) when namespaces are not available to this user.
if ! unshare -n true 2>/dev/null; then
  echo "in_netns: cannot create a network namespace here (needs root or user namespaces); skipped" >&2
  exit 77
fi
exec unshare -n sh -c 'ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && exec "$@"' in_netns "$@"
