#!/usr/bin/env bash
# The CUDA check on an offline GPU machine that has torch but not the env packages (a borrowed
# box, an air-gapped node). Bring, beside the repository:
#   BUNDLE  the env packages for that machine's Python (deploy/offline_bundle.sh 3.12 BUNDLE)
#   GL_DEBS a folder of Debian EGL/GL packages (libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2),
#           unpacked into / here so MuJoCo renders through the NVIDIA EGL driver; optional
#   OUT     where env.txt (driver, versions, an import and a 64x64 render check) and
#           gpu_check.jsonl (one JSON line per preset) go
#
#   BUNDLE=.whl/site312.tar.xz GL_DEBS=.gl OUT=/tmp/out deploy/gpu_check_offline.sh
set -u
bundle=${BUNDLE:?set BUNDLE to the tar.xz from deploy/offline_bundle.sh}
out=${OUT:-/tmp/wmdist-gpu-check}
mkdir -p "$out" /tmp/site
if [ -n "${GL_DEBS:-}" ]; then
    for f in "$GL_DEBS"/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
tar -xJf "$bundle" -C /tmp/site
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=egl
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
[ -f $vendor ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
{
    nvidia-smi; nproc; python3 --version
    python3 -c "import torch, numpy; print(torch.__version__, numpy.__version__, torch.cuda.is_available())"
    python3 -c "import gymnasium, dm_control, mujoco, minatar, ale_py, vizdoom, Box2D, wmdist; print('imports ok')" 2>&1 | tail -3
    python3 -c "from dm_control import suite; e = suite.load('cartpole', 'balance'); e.reset(); print(e.physics.render(64, 64).shape)" 2>&1 | tail -3
} > "$out/env.txt" 2>&1
cat "$out/env.txt"
timeout 480 python3 -m wmdist.bench.gpu_check --seconds 5 2> "$out/stderr.txt" | tee "$out/gpu_check.jsonl"
rc=${PIPESTATUS[0]}
tail -20 "$out/stderr.txt"
exit "$rc"
