#!/usr/bin/env bash
# Run the tests that need a GPU on the lent device machine (see docs/backends.md):
#   bash tools/gpu_tests.sh [pytest args...]
# Installs the carried wheels in .whl/ (filecheck) into /tmp/site, then runs the CUDA and
# runtime tests and the conformance suite on cuda. Logs go to $OUT when it is set.
set -o pipefail
OUT=${OUT:-/tmp/kdsl-gpu-out}
mkdir -p "$OUT"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 KDSL_CACHE_DIR=/tmp/kdsl-cache
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
python3 -c "import cupy, kdsl; print('cupy', cupy.__version__, 'cuda devices', kdsl.get_cuda_device_count())"
python3 -m pytest -q -rf --tb=short -p no:cacheprovider -n 8 tests/cuda tests/runtime "$@" 2>&1 \
    | tee "$OUT/gpu-tests.log" | tail -60
python3 -m kdsl.cli conformance --backend cuda 2>&1 | tee "$OUT/conformance-cuda.log" | tail -25
