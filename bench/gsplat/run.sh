#!/usr/bin/env bash
# The side-by-side benchmark on a lent NVIDIA machine (README.md beside this file): gsplat 1.5.3
# (compiled at first use by its JIT) and gems's GPU engine on the same inputs, one run, one GPU.
# Expects the carried paths .whl (the gsplat wheel), .gl (the Vulkan loader packages) and the
# built gems example target/release/examples/side_by_side. Results go to $OUT (or /tmp/sbs-out).
set -euo pipefail
cd "$(dirname "$0")/../.."
out="${OUT:-/tmp/sbs-out}"
mkdir -p "$out"
dir=/tmp/sbs

for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
if [[ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]]; then
    export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1 WGPU_BACKEND=vulkan
# gsplat compiles its CUDA sources at first use: about 3 minutes on 16 cores for an H100.
export MAX_JOBS="${MAX_JOBS:-16}" TORCH_CUDA_ARCH_LIST="${TORCH_CUDA_ARCH_LIST:-9.0}"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader | tee "$out/gpu.txt"

bin=target/release/examples/side_by_side
"$bin" write "$dir"
python3 bench/gsplat/bench.py "$dir" --out "$out/gsplat.json" 2>&1 | tee "$out/gsplat.log"
"$bin" run "$dir" --out "$out/gems.json" 2>&1 | tee "$out/gems.log"
python3 bench/gsplat/compare.py "$out/gems.json" "$out/gsplat.json" | tee "$out/compare.md"
