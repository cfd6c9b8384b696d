#!/usr/bin/env bash
# Autodiff on the lent GPU machine: the adjoint tests and gradient conformance on cuda,
# the stiff cases, and bench_autodiff.py on cuda (with Warp when /tmp/warp holds it).
#   bash tools/gpu_autodiff.sh
set -o pipefail
OUT=${OUT:-/tmp/kdsl-gpu-out}
mkdir -p "$OUT"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:/tmp/warp:$PWD PYTHONUNBUFFERED=1 KDSL_CACHE_DIR=/tmp/kdsl-cache
python3 -m pytest -q -rf --tb=short -p no:cacheprovider -n 8 kdsl/testing/test_conformance.py \
    -p kdsl.testing.plugin --kdsl-backend=cuda -k grad_ 2>&1 | tee "$OUT/grad-cuda.log" | tail -15
python3 - <<'PY' 2>&1 | tee "$OUT/stiff-cuda.log"
import kdsl
from kdsl.testing import stiff_cases as sc
ks = sc.build(kdsl)
for c in sc.CASES:
    r = sc.evaluate(kdsl, ks, c, "cuda:0")
    print(f"{r['verdict']:16s} {c.name}: d_k {r['d_k']:.6g} (reference {r['d_k_reference']:.6g})")
PY
python3 benchmarks/bench_autodiff.py --device cuda:0 --json "$OUT/autodiff-cuda.json" 2>&1 \
    | grep -v "^Module \|^Warp \|^   " | tee "$OUT/bench-autodiff-cuda.log"
