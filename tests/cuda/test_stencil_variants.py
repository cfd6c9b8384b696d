"""``benchmarks/bench_stencil_variants.py`` rewrites kdsl's generated CUDA C into
variants (32-bit offsets, ``__ldg``, a rows grid, plain division); each rewrite must
still find what it changes in today's code generator, and every variant must build
with NVRTC (compile-only: no GPU needed)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytest.importorskip("cupy_backends.cuda.libs.nvrtc")

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))

import bench_stencil_variants as V  # noqa: E402


@pytest.fixture(scope="module")
def variants():
    return V.variants()


def test_every_variant_builds(variants):
    for workload, vs in variants.items():
        for name, (src, entry) in vs.items():
            counts = V.ptx_counts(src, entry, V._kdsl_built(name))
            assert counts["instructions"] > 10, (workload, name)


def test_rewrites_change_what_they_name(variants):
    jac, clo = variants["jacobi"], variants["cloth"]
    counts = {n: V.ptx_counts(s, e, V._kdsl_built(n)) for n, (s, e) in jac.items()}
    assert counts["kdsl"]["div/rem"] == 1 and counts["kdsl rows"]["div/rem"] == 0
    assert counts["kdsl"]["ld.global.nc"] == 0 and counts["kdsl narrow+ldg"]["ld.global.nc"] == 5
    assert "a.data + (long long)((int)i0 * (int)a.strides[0]" in jac["kdsl offsets32"][0]
    assert "= kd_ifloordiv(" in clo["kdsl"][0] and "= kd_ifloordiv(" not in clo["kdsl div"][0]


def test_a_changed_prologue_is_reported():
    with pytest.raises(RuntimeError, match="prologue changed"):
        V.rows_grid("__global__ void k() {}")
    with pytest.raises(RuntimeError, match="no kd_at accessor"):
        V.offsets32("int x;")


def test_kdsl_fast_entries_as_generated(variants):
    """The backend's own fast entries (``cuda/variants.py``): Jacobi without the
    division, both with every load of a read-only array through the read-only path."""
    jac = variants["jacobi"][V.FAST_ROWS]
    clo = variants["cloth"][V.FAST]
    j = V.ptx_counts(*jac, kdsl_options=True)
    c = V.ptx_counts(*clo, kdsl_options=True)
    assert j["div/rem"] == 0 and j["ld.global.nc"] == 5 and j["ld.global"] == 0
    assert c["ld.global.nc"] == 30 and c["ld.global"] == 0
