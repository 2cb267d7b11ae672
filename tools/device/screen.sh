#!/usr/bin/env bash
# On the lent machine: install the carried wheels (.whl) in a venv beside the image's torch,
# run the training trials of the sweeps runs/NAME (one or several, comma-separated) all at once
# (run_sweep.py), stopping them at STOP_SECONDS so that they save, then pack each runs/NAME
# (without models, replay buffers and frames) into $OUT/NAME.tgz.
#   bash tools/device/screen.sh NAME[,NAME2...] STOP_SECONDS
set -uo pipefail
IFS=, read -r -a names <<< "${1:-}"; stop=${2:-0}
for name in "${names[@]}"; do
    [ -n "$name" ] && [ -d "runs/$name" ] || { echo "screen.sh: no sweep runs/$name" >&2; exit 1; }
done
[ ${#names[@]} -gt 0 ] || { echo 'usage: screen.sh NAME[,NAME2...] STOP_SECONDS' >&2; exit 1; }
start=$SECONDS
# EGL's loader (libglvnd), which the image lacks: `apt-get download libegl1 libglvnd0 ...` into .gl
for f in .gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done; ldconfig
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
[ -e $vendor ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
base=$(python3 -c 'import sys; print(sys.prefix)')
if [ -x /tmp/venv/bin/python ]; then  # a second call on the warm machine: resume
    echo "# set-up: /tmp/venv is there already"
else
    python3 -m venv --without-pip /tmp/venv || exit 1
    site=$(echo /tmp/venv/lib/python3.*/site-packages)
    # the image's packages (torch, numpy, ...) after the venv's own
    python3 -c 'import site; print("\n".join(site.getsitepackages()))' > "$site/image.pth"
    /tmp/venv/bin/python -m pip install -q --no-index --no-deps --no-compile \
        .whl/*.whl || exit 1
    echo "# set-up: $((SECONDS - start)) s ($base)"
fi
export MUJOCO_GL=egl PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,memory.used --format=csv,noheader
/tmp/venv/bin/python -c 'import rclpy, mujoco, torch, stable_baselines3, nav_gym.training.trainer; print("imports ok, cuda", torch.cuda.is_available())
c = mujoco.GLContext(64, 64); c.make_current(); print("EGL ok")' || exit 1
/tmp/venv/bin/python tools/device/run_sweep.py "${names[@]/#/runs/}" --stop-after "$stop"
code=$?
echo "# trials: exit $code after $((SECONDS - start)) s"
for name in "${names[@]}"; do
    tar --exclude='*replay_buffer*' --exclude='*_frames.npz' --exclude='*.zip' \
        -czf "$OUT/$name.tgz" -C runs "$name"
done
ls -la "$OUT"
exit $code
