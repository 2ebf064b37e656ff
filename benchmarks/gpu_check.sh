#!/usr/bin/env bash
# The GPU checks in one call: the CUDA tests, then benchmarks/gpu.py at the issue's sizes
# with VMAS's rows on the same GPU. CI has no GPU; run this where one is at hand.
#
#   bash benchmarks/gpu_check.sh wheels     # here, with pip and network: the Python
#                                           # packages the GPU machine lacks, as wheels
#                                           # for its Python (3.12) in .whl/ (ignored)
#   bash benchmarks/gpu_check.sh run OUT    # there: install .whl/ into /tmp/site, run
#                                           # the tests and the benchmark, write OUT/
#
# What the GPU machine is assumed to have: python3 with torch (CUDA), numpy, pyyaml,
# matplotlib, imageio, tqdm, rich, cloudpickle, six and pytest; the wheels add
# gymnasium, PettingZoo, Stable-Baselines3 and VMAS 1.5.2 (with gym and pyglet, which
# VMAS imports). The C step is not needed there (SWARM_ENVS_NATIVE=0).
set -euo pipefail
cd "$(dirname "$0")/.."
WHEELS=.whl
PY_VERSION=${PY_VERSION:-3.12}

fetch_wheels() {
    mkdir -p "$WHEELS"
    grep -qx "/$WHEELS/" .git/info/exclude 2>/dev/null || echo "/$WHEELS/" >>.git/info/exclude
    local platforms=()
    for p in manylinux_2_28_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64; do
        platforms+=(--platform "$p")
    done
    python3 -m pip download --no-deps --only-binary=:all: --python-version "$PY_VERSION" \
        --implementation cp "${platforms[@]}" --platform any -d "$WHEELS" \
        gymnasium==1.4.0 farama-notifications==0.0.6 pettingzoo==1.27.0 \
        stable-baselines3==2.9.2 pyglet==1.5.27 gym-notices==0.0.8
    # VMAS 1.5.2 and gym 0.26.2 are published as source only (pure Python): built here.
    python3 -m pip wheel --no-deps -q -w "$WHEELS" vmas==1.5.2 gym==0.26.2
    ls -l "$WHEELS"
}

run_checks() {
    local out=${1:?the output folder}
    mkdir -p "$out"
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site "$WHEELS"/*.whl
    export PYTHONPATH="$PWD:/tmp/site" SWARM_ENVS_NATIVE=0 PYTHONUNBUFFERED=1
    (nvidia-smi || echo "no nvidia-smi") 2>&1 | tee "$out/nvidia-smi.txt"
    # Every test that runs on CUDA (they skip without it), then the torch core's own tests.
    python3 -m pytest -q -p no:cacheprovider -k "cuda" \
        tests/test_backends.py tests/test_physics_torch.py tests/test_torch_core.py \
        tests/test_torch_statuses.py 2>&1 | tee "$out/cuda_tests.txt"
    python3 benchmarks/gpu.py --sizes 32x4096,128x64,128x1024,128x4096 --seconds 1 \
        --repeats 3 --peers --json "$out/gpu.json" 2>&1 | tee "$out/gpu.md"
}

case "${1:-}" in
wheels) fetch_wheels ;;
run) run_checks "${2:-${OUT:-gpu_out}}" ;;
*)
    echo "usage: $0 wheels | run OUT" >&2
    exit 2
    ;;
esac
