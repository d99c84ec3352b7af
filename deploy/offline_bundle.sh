#!/usr/bin/env bash
# Pack the environment packages wmdist's presets need, for an offline machine that already has
# torch (a borrowed GPU box, an air-gapped node): the pinned wheels from pyproject.toml for the
# target's Python, unpacked, with assets no preset uses removed, as one tar.xz (~45 MB).
#
#   deploy/offline_bundle.sh 3.12 bundle.tar.xz          # here, with network
#   mkdir -p /tmp/site && tar -xJf bundle.tar.xz -C /tmp/site          # there
#   PYTHONPATH=/tmp/site:. MUJOCO_GL=egl python3 -m wmdist.bench.gpu_check
#
# Ray is left out (about 80 MB): the local runner, which the CUDA check uses, never imports it.
set -euo pipefail
pyver=${1:?usage: deploy/offline_bundle.sh PYTHON_VERSION OUT.tar.xz}
out=$(realpath -m "${2:?usage: deploy/offline_bundle.sh PYTHON_VERSION OUT.tar.xz}")
root=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# pins from pyproject.toml for the env packages, plus their small needs that torch images lack
pins=$(python3 - "$root/pyproject.toml" <<'EOF'
import re, sys, tomllib
deps = tomllib.load(open(sys.argv[1], "rb"))["project"]["dependencies"]
want = {"gymnasium", "dm-control", "mujoco", "minatar", "ale-py", "cma", "box2d", "vizdoom", "redis", "pygame"}
print(" ".join(d.split("#")[0].strip() for d in deps if re.split(r"[<>=\[ ]", d)[0].lower() in want))
EOF
)
extra="dm-env==1.6 farama-notifications pyopengl==3.1.10"
platforms="--platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64"
# shellcheck disable=SC2086  # word splitting of the pin and platform lists is meant
python3 -m pip download -q --no-deps --only-binary=:all: --python-version "$pyver" --implementation cp \
    $platforms -d "$work/wheels" $pins $extra
# shellcheck disable=SC2086
python3 -m pip install -q --no-deps --no-index --no-compile --only-binary=:all: --python-version "$pyver" \
    --implementation cp $platforms --target "$work/site" "$work"/wheels/*.whl
# what no preset loads: dm_control's locomotion and dog assets, MuJoCo's experimental tools,
# pygame's docs, ViZDoom's first IWAD (Take Cover runs on freedoom2)
(cd "$work/site" && rm -rf dm_control/locomotion dm_control/suite/dog_assets dm_control/blender \
    mujoco/experimental pygame/docs pygame/examples pygame/tests vizdoom/freedoom1.wad)
tar -C "$work/site" -cf - . | xz -T0 -6 > "$out"
echo "wrote $out ($(du -h "$out" | cut -f1)) for Python $pyver: $pins $extra"
