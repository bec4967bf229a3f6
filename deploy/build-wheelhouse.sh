#!/usr/bin/env bash
# Build, on a machine with internet, the wheelhouse that deploy/install.sh --wheelhouse
# installs from on a back-end without it: a directory of wheels holding every dependency
# of this checkout and the build backend that builds the checkout itself on the target.
#
#   deploy/build-wheelhouse.sh DIR                     for a target like this machine
#   deploy/build-wheelhouse.sh --python-version 3.11 --platform manylinux_2_36_x86_64 DIR
#                                                      for a Debian 12 amd64 back-end
#                                                      (arm64: manylinux_2_36_aarch64)
#   --python PYTHON   the interpreter whose pip does the work (default python3)
#
# With --python-version or --platform only binary wheels are taken (pip cannot build
# for another machine); every dependency of the receiver has them. The checkout is not
# put in: install.sh builds it on the target, so an upgrade that keeps the dependencies
# needs only the new checkout (a git pull or bundle), not a new wheelhouse. Copy DIR to
# the back-end; `rsync -a --ignore-existing DIR/ backend:/srv/reach-wheelhouse/` sends
# only the wheels it does not hold yet.
set -euo pipefail

usage() { awk 'NR > 1 && /^set -euo/ { exit } NR > 1' "$0" | sed 's/^# \{0,1\}//'; }

python="python3"
target=()
out=""
needs() { [ "$2" -ge 2 ] || { echo "build-wheelhouse.sh: $1 needs a value" >&2; exit 2; }; }
while [ $# -gt 0 ]; do
    case "$1" in
        --python) needs "$1" $#; python="$2"; shift ;;
        --python-version)
            needs "$1" $#
            case "$2" in
                3.[0-9]|3.[0-9][0-9]) ;;
                *) echo "build-wheelhouse.sh: --python-version takes 3.N, not '$2'" >&2; exit 2 ;;
            esac
            # The target's interpreter is CPython: its ABI follows from its version.
            target+=(--python-version "$2" --implementation cp --abi "cp${2/./}")
            shift ;;
        --platform)
            needs "$1" $#
            # pip takes a manylinux_2_N tag literally: a system of glibc 2.N also runs
            # the wheels built for older glibc (2.17 = manylinux2014), so name them all.
            if [[ "$2" =~ ^manylinux_2_([0-9]+)_(.+)$ ]]; then
                for ((n = BASH_REMATCH[1]; n >= 17; n--)); do
                    target+=(--platform "manylinux_2_${n}_${BASH_REMATCH[2]}")
                done
                target+=(--platform "manylinux2014_${BASH_REMATCH[2]}")
            else
                target+=(--platform "$2")
            fi
            shift ;;
        -h|--help) usage; exit 0 ;;
        -*) echo "build-wheelhouse.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
        *) [ -z "$out" ] || { echo "build-wheelhouse.sh: one directory only" >&2; exit 2; }
           out="$1" ;;
    esac
    shift
done
[ -n "$out" ] || { echo "build-wheelhouse.sh: give the wheelhouse directory (see --help)" >&2; exit 2; }

checkout="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
pip=("$python" -m pip --disable-pip-version-check)
binary=()
[ ${#target[@]} -eq 0 ] || binary=(--only-binary=:all: "${target[@]}")

echo "==> the receiver's wheel (only to read its dependencies; not kept)"
"${pip[@]}" wheel --quiet --no-deps --wheel-dir "$work" "$checkout"
wheel="$(ls "$work"/reach_receiver-*.whl)"

echo "==> its dependencies"
"${pip[@]}" download --quiet "${binary[@]}" --dest "$work/deps" "$wheel"

# pyproject.toml's build-system.requires (setuptools), for building the checkout on the
# target; from 70.1 setuptools makes wheels itself, without the package wheel.
echo "==> the build backend"
"${pip[@]}" download --quiet "${binary[@]}" --dest "$work/deps" "setuptools>=70.1"

rm -f "$work"/deps/reach_receiver-*.whl
cp -p "$work"/deps/*.whl "$out/"
echo "==> $(find "$out" -maxdepth 1 -name '*.whl' | wc -l) wheels, $(du -sh "$out" | cut -f1), in $out"
echo "    on the back-end: sudo deploy/install.sh --wheelhouse <its copy of $out>"
