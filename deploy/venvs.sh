# Versioned Python environments of the REACH receiver: sourced by deploy/install.sh.
#
# Each install or upgrade makes a complete new virtual environment in
# /opt/reach/venvs/<UTC time>-<version>-<commit>, checks it, and only then points the
# symlink /opt/reach/venv at it, atomically (a new link renamed over the old one), so the
# unit's ExecStart=/opt/reach/venv/bin/reachd always finds a whole installation: the
# running daemon keeps the environment it started from (its interpreter's path is the
# versioned one), the next start gets the new one, and a rollback is a switch back.
# Names start with the time, so they sort oldest first. /opt/reach/schedules and
# /opt/reach/INSTALLED are links into the current environment, so they follow it.
#
# Uses from install.sh: $root, $dry_run, $live, $python, $checkout, run, say, note, die.

venvs=/opt/reach/venvs
venv=/opt/reach/venv

# The version in the checkout's pyproject.toml, and its commit (or "nogit").
checkout_version() { sed -n 's/^version = "\(.*\)"$/\1/p' "$checkout/pyproject.toml" | head -n 1; }
checkout_commit() {
    git -c safe.directory="$checkout" -C "$checkout" describe --always --dirty 2>/dev/null \
        || echo nogit
}

# The environment the link points at ("" if none): a name in $venvs.
current_venv() {
    local target
    target="$(readlink "$root$venv" 2>/dev/null)" || { echo ""; return; }
    basename "$target"
}

# The kept environments, oldest first, one name a line.
list_venvs() {
    [ -d "$root$venvs" ] || return 0
    find "$root$venvs" -mindepth 1 -maxdepth 1 -type d -printf '%f\n' | LC_ALL=C sort
}

# A new, unused name for an environment of this checkout.
new_venv_name() {
    local base n=1 name
    base="$(date -u +%Y%m%dT%H%M%SZ)-$(checkout_version)-$(checkout_commit)"
    name="$base"
    while [ -e "$root$venvs/$name" ]; do n=$((n + 1)); name="$base.$n"; done
    echo "$name"
}

# Before versioned environments, /opt/reach/venv was a directory: move it among them
# (its scripts name /opt/reach/venv/bin/python, which the link then resolves to it, so
# it still runs if it is rolled back to).
adopt_legacy_venv() {
    if [ -d "$root$venv" ] && [ ! -L "$root$venv" ]; then
        local name
        name="$(date -u -r "$root$venv" +%Y%m%dT%H%M%SZ)-legacy"
        note "moving the environment of the previous layout to $venvs/$name"
        run install -d -m 0755 "$root$venvs"
        run mv -T "$root$venv" "$root$venvs/$name"
    fi
}

# What a new environment must pass before the link points at it, with no network and
# no instrument: consistent dependencies, the commands start, every module of the
# package imports (so each dependency is there and loads with this Python), the site
# file reads.
IMPORT_PROBE='import importlib, pkgutil, sys
import calibration, reach_receiver
from reach_receiver.config.site import load_site
names = [m.name for package in (calibration, reach_receiver)
         for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")
         if not m.name.endswith(".__main__")]
for name in names:
    importlib.import_module(name)
if len(sys.argv) > 1:
    load_site(sys.argv[1])
print(f"{len(names)} modules import" + (f", {sys.argv[1]} reads" if len(sys.argv) > 1 else ""))'

# check_venv DIR SITE: run the checks above on the environment DIR ($root included).
check_venv() {
    local dir="$1" site_file="$2"
    if [ "$dry_run" -eq 1 ]; then
        note "would check $dir: pip check, reachd --version, every module imports, the site reads"
        return 0
    fi
    run "$dir/bin/python" -m pip check --disable-pip-version-check || return 1
    run "$dir/bin/reachd" --version || return 1
    printf '    + %s\n' "$dir/bin/python -c <import every module> $site_file"
    "$dir/bin/python" -c "$IMPORT_PROBE" "$site_file" | sed 's/^/    /'
    return "${PIPESTATUS[0]}"
}

# switch_to NAME: point the link at $venvs/NAME atomically (rename(2) of a new link
# over the old one), and the schedules and INSTALLED links at the link.
switch_to() {
    local name="$1" tmp="$root/opt/reach/.venv.new"
    run ln -sfn "venvs/$name" "$tmp"
    run mv -T "$tmp" "$root$venv"
    local path
    for path in schedules:venv/share/reach/schedules INSTALLED:venv/INSTALLED; do
        local link="$root/opt/reach/${path%%:*}" target="${path#*:}"
        if [ "$(readlink "$link" 2>/dev/null)" != "$target" ]; then
            [ -L "$link" ] || [ ! -e "$link" ] || run rm -rf "$link"  # the previous layout's copy
            run ln -sfn "$target" "$link"
        fi
    done
}

# The environment the running reachd was started from, if any (live system only): its
# interpreter is the first word of its command line.
running_venv() {
    [ "$live" -eq 1 ] || return 0
    local pid
    pid="$(systemctl show -p MainPID --value reachd 2>/dev/null || echo 0)"
    [ -n "$pid" ] && [ "$pid" != 0 ] && [ -r "/proc/$pid/cmdline" ] || return 0
    tr '\0' '\n' < "/proc/$pid/cmdline" | head -n 1 | sed -n "s|^$venvs/\([^/]*\)/.*|\1|p"
}

# prune_venvs KEEP: remove all but the KEEP newest environments, never the current one
# nor the one the running daemon uses.
prune_venvs() {
    local keep="$1" current running name
    current="$(current_venv)"
    running="$(running_venv)"
    list_venvs | head -n "-$keep" | while read -r name; do
        if [ "$name" = "$current" ] || [ "$name" = "$running" ]; then
            continue
        fi
        run rm -rf "${root:?}$venvs/$name"
    done
}

# Switch back to the environment installed before the current one, and restart.
rollback() {
    local current previous="" name
    current="$(current_venv)"
    [ -n "$current" ] || die "$root$venv is not a link to an environment in $root$venvs: nothing to roll back"
    while read -r name; do
        [ "$name" = "$current" ] && break
        previous="$name"
    done < <(list_venvs)
    [ -n "$previous" ] || die "no environment older than $current in $root$venvs to roll back to"
    say "rolling back from $current to $previous"
    if [ "$dry_run" -eq 0 ]; then
        run "$root$venvs/$previous/bin/reachd" --version \
            || die "$root$venvs/$previous does not run: not switching"
    fi
    switch_to "$previous"
    note "the code is that of $previous; system files (unit, udev rules) stay as installed last"
    restart_if_running
}

# Restart reachd if it runs, so that it runs the environment the link points at.
restart_if_running() {
    if [ "$live" -eq 0 ]; then
        note "staging root: reachd is not restarted (live: systemctl try-restart reachd)"
        return 0
    fi
    if [ "$dry_run" -eq 1 ]; then
        note "would run: systemctl try-restart reachd (only if it runs)"
        return 0
    fi
    if ! systemctl is-active --quiet reachd 2>/dev/null; then
        note "reachd is not running: it starts on the new version (systemctl start reachd)"
        return 0
    fi
    if [ "$no_restart" -eq 1 ]; then
        note "reachd still runs the previous version (--no-restart); to switch:"
        note "    systemctl restart reachd     (stops a run in progress)"
        return 0
    fi
    say "restarting reachd (a run in progress stops safely; it resumes if the site says resume: true)"
    if run systemctl try-restart reachd; then
        note "reachd restarted on $(current_venv)"
    else
        note "reachd did not start again: journalctl -u reachd -n 50 says why;"
        note "go back with: $0 --rollback"
        exit 1
    fi
}
