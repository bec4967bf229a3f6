# Removal of the REACH receiver: sourced by deploy/install.sh (--uninstall, --purge).
#
# Removes what install.sh installed: the service (stopped and disabled first), its
# drop-in written by install.sh, the udev, sysusers, tmpfiles, sysctl and modules-load
# files, the links in /usr/local/bin and /opt/reach (every environment). It keeps what
# the site made: the observations and the daemon's state (/var/lib/reach), the site
# file and the timers' schedules (/etc/reach), and the user and group reach, which own
# the data; --purge removes those too. A drop-in the operator wrote (`systemctl edit`)
# is kept, and named.
#
# Uses from install.sh: $root, $dry_run, $live, $purge, $unit, $dropin_dir, $wx_dropin,
# $scripts, $venv, run, say, note.

# The installed files, as install.sh installs them.
installed_files=(
    "$unit"
    /etc/udev/rules.d/99-reach.rules
    /etc/sysusers.d/reach.conf
    /etc/tmpfiles.d/reach.conf
    /etc/sysctl.d/90-reach.conf
    /etc/modules-load.d/reach.conf
)

uninstall() {
    say "removing the REACH receiver from ${root:-/}$([ "$dry_run" -eq 1 ] && echo ' (dry run)')"
    if [ "$live" -eq 1 ]; then
        say "stopping and disabling reachd (a run in progress stops safely)"
        if [ "$dry_run" -eq 1 ] || systemctl cat reachd >/dev/null 2>&1; then
            run systemctl disable --now reachd
        else
            note "no unit reachd"
        fi
    fi

    say "system files"
    local path
    for path in "${installed_files[@]}" "$wx_dropin"; do
        if [ -e "$root$path" ] || [ "$dry_run" -eq 1 ]; then run rm -f "$root$path"; fi
    done
    if [ -d "$root$dropin_dir" ]; then
        if [ -z "$(ls -A "$root$dropin_dir")" ]; then
            run rmdir "$root$dropin_dir"
        else
            note "kept $root$dropin_dir: drop-ins not written by install.sh:"
            note "    $(ls "$root$dropin_dir" | tr '\n' ' ')"
        fi
    fi

    say "commands and code"
    local script
    for script in "${scripts[@]}"; do
        # Only the links install.sh made; a command of that name from elsewhere stays.
        if [ "$(readlink "$root/usr/local/bin/$script" 2>/dev/null)" = "$venv/bin/$script" ]; then
            run rm -f "$root/usr/local/bin/$script"
        fi
    done
    if [ -e "$root/opt/reach" ] || [ "$dry_run" -eq 1 ]; then
        run rm -rf "$root/opt/reach"
    fi

    if [ "$live" -eq 1 ]; then
        say "systemd and udev"
        run systemctl daemon-reload
        if [ "$dry_run" -eq 1 ] || command -v udevadm >/dev/null; then
            run udevadm control --reload
        fi
        note "net.core.rmem_max and the loaded modules stay as they are until the next boot"
    fi

    if [ "$purge" -eq 1 ]; then
        say "purging the data, the site file and the user reach (--purge)"
        for path in /var/lib/reach /var/cache/reach /etc/reach; do
            if [ -e "$root$path" ]; then
                note "$root$path: $(du -sh "$root$path" 2>/dev/null | cut -f1)"
                run rm -rf "$root$path"
            fi
        done
        local at=()
        [ "$live" -eq 1 ] || at=(--root "$root")
        if grep -q '^reach:' "$root/etc/passwd" 2>/dev/null || [ "$dry_run" -eq 1 ]; then
            run userdel "${at[@]}" reach
        fi
        if grep -q '^reach:' "$root/etc/group" 2>/dev/null; then
            run groupdel "${at[@]}" reach
        fi
    else
        say "kept (remove them with --uninstall --purge)"
        for path in /var/lib/reach /etc/reach; do
            if [ -e "$root$path" ]; then note "$root$path"; fi
        done
        note "the user and group reach"
    fi
    say "done"
}
