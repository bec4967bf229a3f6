#!/usr/bin/env bash
# Install, upgrade, roll back or remove the REACH receiver daemon on a Debian back-end,
# from the checkout this script is in. Run as root; safe to run again (that is how to
# upgrade: each install is a new environment, switched to only once it is complete).
#
#   deploy/install.sh                   install or upgrade from the package index
#   deploy/install.sh --wheelhouse DIR  the same with no network: the dependencies and the
#                                       build backend from DIR (deploy/build-wheelhouse.sh)
#   deploy/install.sh --rollback        switch back to the previous environment, restart
#   deploy/install.sh --uninstall       remove the service and the code; keep the data,
#                                       /etc/reach and the user reach (--purge: those too)
#   --dry-run       print what it would do, change nothing
#   --root DIR      act on the staging root DIR (tests, images; also --prefix): nothing
#                   outside DIR is touched, and the steps that act on the running system
#                   (udev, systemctl, sysctl, modules, checks) are skipped
#   --no-restart    leave a running reachd on its version (the switch applies at its
#                   next start); otherwise a running reachd is restarted after the switch
#   --keep N        environments kept, the current one included (default 3)
#   --skip-venv     leave the environments alone (system files only)
#
# An install makes /opt/reach/venvs/<time>-<version>-<commit> with this checkout
# pip-installed in it, checks it (pip check, reachd --version, every module imports, the
# site file reads), then installs the system files (unit, udev rules, sysusers, tmpfiles,
# sysctl, modules-load), /etc/reach/site.yaml from deploy/site.example.yaml if there is
# none, applies them (sysusers, tmpfiles, sysctl, modules, udev, daemon-reload), points
# the link /opt/reach/venv (the unit's ExecStart) at the new environment atomically,
# restarts reachd if it was running, runs `reachd --check` if it is not, and removes all
# but the newest environments. deploy/README.md tells the whole procedure.
set -euo pipefail

usage() { awk 'NR > 1 && /^set -euo/ { exit } NR > 1' "$0" | sed 's/^# \{0,1\}//'; }

dry_run=0
prefix=""
skip_venv=0
no_restart=0
wheelhouse=""
mode=install
purge=0
keep=3
needs() { [ "$2" -ge 2 ] || { echo "install.sh: $1 needs a value (see --help)" >&2; exit 2; }; }
while [ $# -gt 0 ]; do
    case "$1" in
        --dry-run) dry_run=1 ;;
        --root|--prefix) needs "$1" $#; prefix="$2"; shift ;;
        --root=*|--prefix=*) prefix="${1#*=}" ;;
        --wheelhouse) needs "$1" $#; wheelhouse="$2"; shift ;;
        --wheelhouse=*) wheelhouse="${1#*=}" ;;
        --keep) needs "$1" $#; keep="$2"; shift ;;
        --keep=*) keep="${1#*=}" ;;
        --rollback) mode=rollback ;;
        --uninstall) mode=uninstall ;;
        --purge) purge=1 ;;
        --no-restart) no_restart=1 ;;
        --skip-venv) skip_venv=1 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "install.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
    shift
done
case "$keep" in
    ''|*[!0-9]*|0) echo "install.sh: --keep takes a whole number of at least 1, not '$keep'" >&2; exit 2 ;;
esac
if [ "$purge" -eq 1 ] && [ "$mode" != uninstall ]; then
    echo "install.sh: --purge goes with --uninstall" >&2; exit 2
fi
if [ -n "$wheelhouse" ]; then
    [ "$mode" = install ] || { echo "install.sh: --wheelhouse goes with an install" >&2; exit 2; }
    [ -d "$wheelhouse" ] || { echo "install.sh: --wheelhouse $wheelhouse: no such directory" >&2; exit 2; }
    wheelhouse="$(cd "$wheelhouse" && pwd)"
    compgen -G "$wheelhouse/*.whl" >/dev/null \
        || { echo "install.sh: --wheelhouse $wheelhouse holds no wheels (*.whl)" >&2; exit 2; }
fi

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
# shellcheck source=deploy/venvs.sh
. "$deploy/venvs.sh"
# shellcheck source=deploy/uninstall.sh
. "$deploy/uninstall.sh"

# --- preflight ---------------------------------------------------------------------
if [ "$live" -eq 1 ] && [ "$dry_run" -eq 0 ] && [ "$(id -u)" -ne 0 ]; then
    die "run as root (sudo $0), or try --dry-run"
fi
# One install.sh at a time: two would build, switch and prune over each other.
if [ "$dry_run" -eq 0 ]; then
    mkdir -p "$root/opt/reach"
    exec 9>"$root/opt/reach/.install.lock"
    flock -n 9 || die "another install.sh is working on ${root:-/} (it holds $root/opt/reach/.install.lock)"
fi
case "$mode" in
    rollback) rollback; say "done"; exit 0 ;;
    uninstall) uninstall; exit 0 ;;
esac
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

# --- the Python package: a new environment, complete and checked before anything changes
# The site file the new environment is checked against: the installed one, else the
# example that becomes it.
check_site="$root$site"
[ -f "$check_site" ] || check_site="$deploy/site.example.yaml"
# build_venv DIR: make the environment DIR and install this checkout in it.
build_venv() {
    local dir="$1" source
    run "$python" -m venv "$dir" || return 1
    if [ -n "$wheelhouse" ]; then
        source="the wheelhouse $wheelhouse"
        # The checkout is built here too, with the build backend from the wheelhouse.
        run "$dir/bin/python" -m pip install --disable-pip-version-check --quiet \
            --no-index --find-links "$wheelhouse" "$checkout" || return 1
    else
        source="the package index"
        run "$dir/bin/python" -m pip install --disable-pip-version-check --quiet "$checkout" \
            || return 1
    fi
    # The shipped schedules and what was installed, kept with the code they go with.
    run install -d -m 0755 "$dir/share/reach/schedules" || return 1
    for schedule in "$checkout"/schedules/*.yaml; do
        install_file "$schedule" "${dir#"$root"}/share/reach/schedules/$(basename "$schedule")" 0644
    done
    if [ "$dry_run" -eq 0 ]; then
        {
            echo "checkout: $checkout"
            echo "commit: $(checkout_commit)"
            echo "version: $(checkout_version)"
            echo "from: $source"
            echo "installed: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
        } > "$dir/INSTALLED"
    fi
    check_venv "$dir" "$check_site"
}
new=""
if [ "$skip_venv" -eq 1 ]; then
    say "Python environment: skipped (--skip-venv)"
else
    new="$venvs/$(new_venv_name)"
    say "new Python environment $root$new (from ${wheelhouse:-the package index})"
    run install -d -m 0755 "$root$venvs"
    if ! build_venv "$root$new"; then
        [ "$dry_run" -eq 1 ] || rm -rf "${root:?}$new"
        if [ -n "$wheelhouse" ]; then
            die "the new environment failed (above) and was removed; nothing else changed. A dependency missing from $wheelhouse? Rebuild it with deploy/build-wheelhouse.sh"
        fi
        die "the new environment failed (above) and was removed; nothing else changed"
    fi
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

# --- the running system (not in a staging root) ---------------------------------------
# Loads the site's TC-08 library with the daemon's stack (the MemoryDenyWriteExecute test).
probe='import sys, numpy, scipy.linalg, h5py, astropy.time
from reach_receiver.config.site import load_site
from reach_receiver.transports.tc08_library import load_libusbtc08
library = load_site(sys.argv[1]).devices.tc08.library
load_libusbtc08(library)
print("loaded", library or "libusbtc08 (default search)")'
if [ "$live" -eq 0 ]; then
    say "staging root: not touching the running system (sysctl, modules, udev, systemd, checks)"
else
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
    probe_python="${new:-$venv}/bin/python"
    if [ "$dry_run" -eq 1 ]; then
        note "would load the site's libusbtc08 under MemoryDenyWriteExecute=yes (systemd-run)"
        note "and write $wx_dropin only if that fails"
    elif [ ! -x "$probe_python" ]; then
        note "no $probe_python: skipped"
    elif ! reason="$("$probe_python" -c "$probe" "$site" 2>&1)"; then
        note "it does not load even outside the sandbox:"
        note "$(printf '%s\n' "$reason" | tail -n 1)"
        note "(install Pico's libusbtc08 package, set devices.tc08.library in $site, fix"
        note "what the line above says), then run install.sh again"
    elif systemd-run --quiet --wait --pipe --collect --property=User=reach \
            --property=MemoryDenyWriteExecute=yes "$probe_python" -c "$probe" "$site"; then
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
fi

# --- the switch: only now does /opt/reach/venv point at the new environment ----------
if [ -n "$new" ]; then
    say "switching $root$venv to $(basename "$new")"
    adopt_legacy_venv
    switch_to "$(basename "$new")"
    say "commands in /usr/local/bin"
    run install -d -m 0755 "$root/usr/local/bin"
    for script in "${scripts[@]}"; do
        run ln -sfn "$venv/bin/$script" "$root/usr/local/bin/$script"
    done
    restart_if_running
fi

if [ "$live" -eq 1 ]; then
    say "reachd --check (as user reach)"
    if [ "$dry_run" -eq 1 ]; then
        note "would run (if reachd is not running): runuser -u reach -g reach -G dialout -- $venv/bin/reachd --check --site $site"
    elif systemctl is-active --quiet reachd 2>/dev/null; then
        # Its probes open the instruments, which the running daemon holds.
        note "reachd is running: its start is the check (systemctl status reachd); run"
        note "reachd --check while it is stopped"
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
        note "$venv/bin/reachd does not exist: no check"
    fi
fi

if [ -n "$new" ]; then
    say "environments: keeping the newest $keep in $root$venvs"
    prune_venvs "$keep"
fi
if [ "$live" -eq 0 ]; then
    say "done (staged in $root)"
    exit 0
fi
say "done"
if [ "$dry_run" -eq 1 ] || ! systemctl is-active --quiet reachd 2>/dev/null; then
    note "start the service now and at every boot:  systemctl enable --now reachd"
fi
note "follow it:  journalctl -u reachd -f   and   systemctl status reachd"
note "go back to the previous version:  $0 --rollback"
