#!/usr/bin/env bash
# Download the wheels a sweep trial needs beyond an image with torch (the lent machine's), for
# Python $1 (default 3.12), into $2 (default .whl): ROS 2's client library and messages,
# MuJoCo, Gymnasium and Stable-Baselines3 (tools/device/wheels.txt), and this package.
set -euo pipefail
py=${1:-3.12}
dest=${2:-.whl}
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$dest"
platforms=()
for n in 1 2014 2_17 2_24 2_27 2_28 2_31 2_34 2_35 2_39; do
    case $n in 1|2014) platforms+=(--platform "manylinux${n}_x86_64");;
               *) platforms+=(--platform "manylinux_${n}_x86_64");; esac
done
python3 -m pip download -q --no-deps --only-binary=:all: --python-version "$py" \
    --implementation cp "${platforms[@]}" -d "$dest" -r "$here/wheels.txt"
python3 -m pip wheel -q --no-deps -w "$dest" "$here/../.."
du -sh "$dest"
