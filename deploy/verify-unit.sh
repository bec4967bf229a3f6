#!/usr/bin/env bash
# Check a unit file (default: deploy/reachd.service) with `systemd-analyze verify` and
# hold its sandbox to an exposure level with `systemd-analyze security --offline`, on a
# machine where it is not installed and systemd does not run (CI's container). Used by
# .ci/run and tests/test_deploy.py; needs systemd-analyze (Debian's `systemd` package).
#
# How: `verify` refuses a unit whose ExecStart= binary does not exist, and the real
# unit names /opt/reach/venv/bin/reachd. Rather than edit the unit, it is checked
# unchanged inside a throw-away root (--root=, which systemd 252 supports for verify and
# security): the unit in <root>/etc/systemd/system, the system's own units (for
# network-online.target, time-sync.target, ...) copied to <root>/usr/lib/systemd/system,
# and at each Exec*= path a copy of the real command of that name from PATH (reachd),
# or, while that is not installed, of reach-run. Inside a --root, verify looks for the
# binary inside the root and for the unit by name: hence the copies. It exits 0 despite
# warnings (an unknown key, a value it cannot parse), so any output at all fails here.
set -euo pipefail

unit="${1:-$(dirname "${BASH_SOURCE[0]}")/reachd.service}"
name="$(basename "$unit")"
# Overall exposure allowed, x10 (reachd.service rates 1.9 "OK" in systemd 252).
threshold="${REACH_UNIT_EXPOSURE_MAX:-25}"

command -v systemd-analyze >/dev/null || {
    echo "verify-unit.sh: systemd-analyze not found (apt-get install systemd)" >&2
    exit 3
}
root="$(mktemp -d)"
trap 'rm -rf "$root"' EXIT

system_units=/usr/lib/systemd/system
[ -d "$system_units" ] || system_units=/lib/systemd/system
mkdir -p "$root/etc/systemd/system" "$root/usr/lib/systemd"
cp -r "$system_units" "$root/usr/lib/systemd/system"
cp "$unit" "$root/etc/systemd/system/$name"

# Exec lines may carry prefixes (-, @, :, +, !) before the absolute path.
sed -n 's/^Exec[A-Za-z]*=[-@:+!]*\(\/[^ ]*\).*/\1/p' "$unit" | sort -u |
while read -r exe; do
    stand_in="$(command -v "$(basename "$exe")" || command -v reach-run || true)"
    [ -n "$stand_in" ] || { echo "verify-unit.sh: no $(basename "$exe") or reach-run on PATH" >&2; exit 1; }
    install -D -m 0755 "$stand_in" "$root$exe"
    echo "verify-unit.sh: $exe stood in for by $stand_in"
done

status=0
output="$(systemd-analyze verify --root="$root" "$name" 2>&1)" || status=$?
if [ "$status" -ne 0 ] || [ -n "$output" ]; then
    printf '%s\n' "$output"
    echo "verify-unit.sh: systemd-analyze verify $unit: FAILED (exit $status)" >&2
    exit 1
fi
echo "verify-unit.sh: systemd-analyze verify $unit: no warnings ($(systemd-analyze --version | head -1))"

status=0
output="$(systemd-analyze security --offline=yes --root="$root" --threshold="$threshold" \
    --no-pager "$name" 2>&1)" || status=$?
printf '%s\n' "$output" | grep 'Overall exposure' || true
if [ "$status" -ne 0 ]; then
    printf '%s\n' "$output"
    echo "verify-unit.sh: exposure above $threshold/100: the sandbox was weakened" >&2
    exit 1
fi
