#!/usr/bin/env bash
# The multi-GPU checks of issue 19 on a machine with two GPUs or more (docs/multigpu.md):
#   bash tools/multigpu_check.sh [--quick]
# 1. pytest: several GPUs in one process, strips over GPUs (one process and NCCL ranks),
#    the torch.distributed example over NCCL, and JAX over every GPU;
# 2. the examples themselves: torchrun over every GPU (NCCL), JAX over every GPU;
# 3. the scaling benchmark (the heat grid at 8192^2 on 1, 2, 4, 8 GPUs, and peer copies),
#    which --quick skips.
# Installs the carried wheels in .whl/ (if any) into /tmp/site. Logs and the benchmark's
# JSON go to $OUT when it is set. Exits non-zero if any step failed.
set -o pipefail
OUT=${OUT:-/tmp/kdsl-multigpu-out}
mkdir -p "$OUT"
if compgen -G ".whl/*.whl" >/dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl || exit 1
fi
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 KDSL_CACHE_DIR=/tmp/kdsl-cache
# NVLink multicast stays off: it can take a shared host's GPUs out of service.
export NCCL_NVLS_ENABLE=0 TORCH_SYMM_MEM_DISABLE_MULTICAST=1 NVSHMEM_DISABLE_NVLS=1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
nvidia-smi topo -m 2>/dev/null | head -12
GPUS=$(python3 -c "import kdsl; print(kdsl.get_cuda_device_count())") || exit 1
echo "kdsl sees $GPUS CUDA devices"
if [ "$GPUS" -lt 2 ]; then
    echo "multigpu_check: needs two GPUs or more" >&2
    exit 2
fi
status=0
step() {  # step NAME COMMAND...: run it with a time limit, log it, remember a failure
    local name=$1
    shift
    echo "== $name"
    timeout 900 "$@" 2>&1 | tee "$OUT/$name.log" | tail -25 || { echo "== $name FAILED"; status=1; }
}
step pytest python3 -m pytest -q -rfs --tb=short -p no:cacheprovider -p no:xdist \
    tests/runtime/test_multi_gpu.py tests/scenes/test_strips.py tests/scenes/test_distributed.py \
    tests/interop/test_torch_distributed.py tests/interop/test_jax_distributed.py \
    tests/interop/test_jax_ffi.py::test_shard_map_over_devices \
    tests/interop/test_jax_ffi.py::test_gpu_kernel_callable_and_callback
step torch-example python3 -m torch.distributed.run --standalone --nproc-per-node="$GPUS" \
    examples/distributed_torch.py --device cuda --points 1000000 --iters 20
step jax-example python3 examples/distributed_jax.py
step scenes-nccl python3 -m torch.distributed.run --standalone --nproc-per-node="$GPUS" \
    -m kdsl.scenes.distributed --device cuda --scene wave --grid 1024 --steps 50 --check
if [ "${1:-}" != "--quick" ]; then
    step bench python3 benchmarks/bench_multigpu.py --json "$OUT/multigpu.json"
fi
echo "multigpu_check: $([ $status = 0 ] && echo passed || echo FAILED)"
exit $status
