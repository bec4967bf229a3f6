#!/usr/bin/env bash
# Install (or update) the REACH receiver daemon on a Debian back-end, from the checkout
# this script is in. Run as root; safe to run again (that is how to update).
#
#   deploy/install.sh                 install into / and check the installation
#   deploy/install.sh --dry-run       print what it would do, change nothing
#   deploy/install.sh --prefix DIR    install into the staging root DIR (tests, images):
#                                     nothing outside DIR is touched, and the steps that
#                                     act on the running system (udev, systemctl,
#                                     sysctl, modules, checks) are skipped
#   deploy/install.sh --skip-venv     leave /opt/reach/venv alone (system files only)
#
# What it does: a virtual environment /opt/reach/venv with this checkout pip-installed
# in it (the only network access: pip, for the package and its dependencies); links in
# /usr/local/bin; the schedules in /opt/reach/schedules; the systemd unit, udev rules,
# sysusers, tmpfiles, sysctl and modules-load files; /etc/reach/site.yaml from
# deploy/site.example.yaml if there is none; then systemd-sysusers, systemd-tmpfiles,
# sysctl, modules, udev reload and trigger, daemon-reload, and `reachd --check`.
# It never enables, starts or restarts the service: the operator does (a restart stops a
# run in progress). deploy/README.md tells the whole procedure.
set -euo pipefail

usage() { sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'; }

dry_run=0
prefix=""
skip_venv=0
while [ $# -gt 0 ]; do
    case "$1" in
        --dry-run) dry_run=1 ;;
        --prefix) [ $# -ge 2 ] || { echo "install.sh: --prefix needs a directory" >&2; exit 2; }
                  prefix="$2"; shift ;;
        --prefix=*) prefix="${1#--prefix=}" ;;
        --skip-venv) skip_venv=1 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "install.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
    shift
done

deploy="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
checkout="$(dirname "$deploy")"
# The staging root ("" for the live system); every path below is written $root/<path>.
root=""
if [ -n "$prefix" ]; then
    [ "$dry_run" -eq 1 ] || mkdir -p "$prefix"
    root="$(cd "$prefix" 2>/dev/null && pwd || echo "$prefix")"
    root="${root%/}"
fi
live=1; [ -z "$root" ] || live=0

venv=/opt/reach/venv
python="${PYTHON:-python3}"
site=/etc/reach/site.yaml
unit=/etc/systemd/system/reachd.service
dropin_dir=/etc/systemd/system/reachd.service.d
wx_dropin="$dropin_dir/50-memory-deny-write-execute.conf"
scripts=(reachd reach-run reach-cal reach-sim)

say() { printf '==> %s\n' "$*"; }
note() { printf '    %s\n' "$*"; }
die() { printf 'install.sh: %s\n' "$*" >&2; exit 1; }
# Run a command, or with --dry-run print it.
run() {
    if [ "$dry_run" -eq 1 ]; then
        printf '    would run: %s\n' "$*"
    else
        printf '    + %s\n' "$*"
        "$@"
    fi
}
# install_file SRC DEST MODE: copy SRC to $root/DEST (making directories) unless equal.
install_file() {
    local src="$1" dest="$root$2" mode="$3"
    if [ "$dry_run" -eq 1 ]; then
        printf '    would install %s -> %s (mode %s)\n' "${src#"$checkout"/}" "$dest" "$mode"
    elif [ -f "$dest" ] && cmp -s "$src" "$dest"; then
        printf '    unchanged %s\n' "$dest"
        chmod "$mode" "$dest"
    else
        printf '    install %s -> %s\n' "${src#"$checkout"/}" "$dest"
        install -D -m "$mode" "$src" "$dest"
    fi
}
# The gid of group reach in the (staging) root's /etc/group, empty if not there yet.
reach_gid() { awk -F: '$1 == "reach" { print $3 }' "$root/etc/group" 2>/dev/null || true; }

# --- preflight ---------------------------------------------------------------------
if [ "$live" -eq 1 ] && [ "$dry_run" -eq 0 ] && [ "$(id -u)" -ne 0 ]; then
    die "run as root (sudo $0), or try --dry-run"
fi
for tool in systemd-sysusers systemd-tmpfiles; do
    command -v "$tool" >/dev/null || [ "$dry_run" -eq 1 ] \
        || die "$tool not found: this is meant for a Debian system with systemd"
done
if [ "$skip_venv" -eq 0 ] && [ "$dry_run" -eq 0 ]; then
    "$python" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null \
        || die "$python is missing or older than 3.10 (Debian: apt-get install python3)"
    "$python" -c 'import ensurepip, venv' 2>/dev/null \
        || die "$python cannot make virtual environments: apt-get install python3-venv"
fi
say "installing from $checkout into ${root:-/}$([ "$dry_run" -eq 1 ] && echo ' (dry run)')"

# --- the Python package ------------------------------------------------------------
if [ "$skip_venv" -eq 1 ]; then
    say "virtual environment: skipped (--skip-venv)"
else
    say "virtual environment $root$venv"
    # A venv made by an older Python (a Debian upgrade) no longer runs: make it afresh.
    if [ -e "$root$venv" ] && ! "$root$venv/bin/python" -c '' 2>/dev/null; then
        run rm -rf "$root$venv"
    fi
    if [ ! -x "$root$venv/bin/python" ]; then
        run "$python" -m venv "$root$venv"
    fi
    # pip rebuilds and reinstalls a local directory even at the same version, so this
    # also updates; dependencies move only when the new version needs it.
    run "$root$venv/bin/python" -m pip install --disable-pip-version-check --quiet "$checkout"
fi
say "commands in /usr/local/bin"
run install -d -m 0755 "$root/usr/local/bin"
for script in "${scripts[@]}"; do
    if [ "$dry_run" -eq 1 ] || [ -x "$root$venv/bin/$script" ]; then
        run ln -sfn "$venv/bin/$script" "$root/usr/local/bin/$script"
    else
        note "$script: no $root$venv/bin/$script, no link"
    fi
done

say "schedules in $root/opt/reach/schedules (replaced on every install)"
run rm -rf "$root/opt/reach/schedules"
run install -d -m 0755 "$root/opt/reach/schedules"
for schedule in "$checkout"/schedules/*.yaml; do
    install_file "$schedule" "/opt/reach/schedules/$(basename "$schedule")" 0644
done
if [ "$dry_run" -eq 1 ]; then
    note "would record the installed version in $root/opt/reach/INSTALLED"
else
    {
        echo "checkout: $checkout"
        echo "commit: $(git -c safe.directory="$checkout" -C "$checkout" describe --always --dirty 2>/dev/null || echo unknown)"
        echo "installed: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
    } > "$root/opt/reach/INSTALLED"
fi

# --- system files --------------------------------------------------------------------
say "system files"
install_file "$deploy/reachd.service" "$unit" 0644
install_file "$deploy/udev/99-reach.rules" /etc/udev/rules.d/99-reach.rules 0644
install_file "$deploy/sysusers.d/reach.conf" /etc/sysusers.d/reach.conf 0644
install_file "$deploy/tmpfiles.d/reach.conf" /etc/tmpfiles.d/reach.conf 0644
install_file "$deploy/sysctl.d/90-reach.conf" /etc/sysctl.d/90-reach.conf 0644
install_file "$deploy/modules-load.d/reach.conf" /etc/modules-load.d/reach.conf 0644

say "user and group reach, /etc/reach"
# The group must exist before udev reads rules that name it, and before tmpfiles.
if [ "$live" -eq 1 ]; then
    run systemd-sysusers /etc/sysusers.d/reach.conf
    run systemd-tmpfiles --create /etc/tmpfiles.d/reach.conf
else
    run systemd-sysusers --root="$root" "$root/etc/sysusers.d/reach.conf"
    run systemd-tmpfiles --root="$root" --create "$root/etc/tmpfiles.d/reach.conf"
fi

say "site file $root$site"
install_file "$deploy/site.example.yaml" /etc/reach/site.example.yaml 0640
if [ -e "$root$site" ]; then
    note "kept the existing $root$site (compare with site.example.yaml beside it)"
else
    install_file "$deploy/site.example.yaml" "$site" 0640
    note "EDIT IT: the VNA's address, the TC-08 library, the test load's S11 file"
fi
if [ "$dry_run" -eq 1 ]; then
    note "would give $root/etc/reach/site*.yaml to group reach"
else
    gid="$(reach_gid)"
    [ -n "$gid" ] || die "group reach is missing from $root/etc/group after systemd-sysusers"
    chgrp "$gid" "$root$site" "$root/etc/reach/site.example.yaml"
fi

if [ "$live" -eq 0 ]; then
    say "staging root: not touching the running system (sysctl, modules, udev, systemd, checks)"
    say "done (staged in $root)"
    exit 0
fi

# --- the running system --------------------------------------------------------------
say "kernel settings and modules"
sysctl_bin="$(command -v systemd-sysctl || echo /lib/systemd/systemd-sysctl)"
run "$sysctl_bin" /etc/sysctl.d/90-reach.conf
run systemctl restart systemd-modules-load.service

say "udev rules"
if [ "$dry_run" -eq 1 ] || command -v udevadm >/dev/null; then
    run udevadm control --reload
    run udevadm trigger --action=change --subsystem-match=usb --subsystem-match=tty \
        --subsystem-match=hidraw
    run udevadm settle --timeout=30
else
    note "udevadm not found (apt-get install udev): rules not applied"
fi

say "systemd"
run systemctl daemon-reload

# MemoryDenyWriteExecute=yes refuses libraries that need an executable stack or text
# relocations. Try the Python stack and the site's TC-08 library under exactly that
# setting, as the service's user; turn the setting off in a drop-in only if that fails.
say "MemoryDenyWriteExecute and the TC-08 library"
probe='import sys, numpy, scipy.linalg, h5py, astropy.time
from reach_receiver.config.site import load_site
from reach_receiver.transports.tc08_library import load_libusbtc08
library = load_site(sys.argv[1]).devices.tc08.library
load_libusbtc08(library)
print("loaded", library or "libusbtc08 (default search)")'
if [ "$dry_run" -eq 1 ]; then
    note "would load the site's libusbtc08 under MemoryDenyWriteExecute=yes (systemd-run)"
    note "and write $wx_dropin only if that fails"
elif [ ! -x "$venv/bin/python" ]; then
    note "no $venv: skipped"
elif ! reason="$("$venv/bin/python" -c "$probe" "$site" 2>&1)"; then
    note "it does not load even outside the sandbox:"
    note "$(printf '%s\n' "$reason" | tail -n 1)"
    note "(install Pico's libusbtc08 package, set devices.tc08.library in $site, fix"
    note "what the line above says), then run install.sh again"
elif systemd-run --quiet --wait --pipe --collect --property=User=reach \
        --property=MemoryDenyWriteExecute=yes "$venv/bin/python" -c "$probe" "$site"; then
    if [ -e "$wx_dropin" ]; then run rm -f "$wx_dropin"; run systemctl daemon-reload; fi
    note "MemoryDenyWriteExecute=yes stays on"
else
    note "the TC-08 library does not load under MemoryDenyWriteExecute=yes: turning it"
    note "off in $wx_dropin"
    mkdir -p "$dropin_dir"
    printf '%s\n' "# Written by deploy/install.sh: this site's libusbtc08 needs W+X memory." \
        "[Service]" "MemoryDenyWriteExecute=no" > "$wx_dropin"
    run systemctl daemon-reload
fi

say "reachd --check (as user reach)"
if [ "$dry_run" -eq 1 ]; then
    note "would run: runuser -u reach -g reach -G dialout -- $venv/bin/reachd --check --site $site"
elif [ -x "$venv/bin/reachd" ]; then
    # While the service is stopped its runtime directory does not exist: make it as
    # systemd would (the service adopts it on start and removes it on stop).
    [ -d /run/reach ] || install -d -m 0750 -o reach -g reach /run/reach
    set +e
    runuser -u reach -g reach -G dialout -- env REACH_SITE="$site" \
        "$venv/bin/reachd" --check --site "$site"
    status=$?
    set -e
    if [ "$status" -eq 0 ]; then
        note "reachd --check: all checks passed"
    else
        note "reachd --check FAILED (exit $status): fix what it lists above, then run"
        note "    runuser -u reach -g reach -G dialout -- $venv/bin/reachd --check"
    fi
else
    note "$venv/bin/reachd does not exist in this version: no check"
fi

say "done"
if [ "$dry_run" -eq 0 ] && systemctl is-active --quiet reachd 2>/dev/null; then
    note "reachd is running the previous version. To switch (this stops a run in progress"
    note "safely; 'systemctl status reachd' shows whether one is): systemctl restart reachd"
else
    note "start the service now and at every boot:  systemctl enable --now reachd"
    note "then follow it:  journalctl -u reachd -f   and   systemctl status reachd"
fi
