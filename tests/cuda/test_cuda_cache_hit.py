"""A cuda kernel whose cubin is in the kernel cache loads with no lowering and no NVRTC.

Runs without a GPU: the cubin is compiled for sm_90 (``arch`` option) and never loaded
onto a device; what is checked is that the second compile reads it from the disk cache
while CUDA C generation and NVRTC compilation are made to fail.
"""

from __future__ import annotations

import pytest

pytest.importorskip("cupy_backends.cuda.libs.nvrtc")

from kdsl.backends.cuda import BACKEND, lower, nvrtc
from kdsl.backends.cuda.lower import entry_name, generate
from kdsl.compiler import cache, compile_kernel
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline
from kdsl.testing.cases.programs import make_programs

PROGRAMS = make_programs()  # fresh kernel objects: saxpy, integrate (vec3), nbody...
scale_add = PROGRAMS["saxpy"]


def _refuse(*args, **kwargs):
    raise AssertionError("a cache hit must not lower or compile")


def test_a_cache_hit_neither_lowers_nor_compiles(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path))
    options = {"arch": "sm_90"}
    cold = compile_kernel(BACKEND, scale_add, options=options)
    cold.payload.cubin("sm_90")
    assert cache.STATS.builds >= 1
    cache.MEMORY.clear()  # a fresh process: only the disk layer has the cubin
    monkeypatch.setattr(lower, "generate", _refuse)
    monkeypatch.setattr(nvrtc, "compile_source", _refuse)
    hits = cache.STATS.disk_hits
    warm = compile_kernel(BACKEND, scale_add, options=options)
    assert cache.STATS.disk_hits == hits + 1
    assert warm.payload.entry == cold.payload.entry
    assert warm.payload.cubin("sm_90") == cold.payload.cubin("sm_90")


@pytest.mark.parametrize("kernel", [PROGRAMS["saxpy"], PROGRAMS["integrate"], PROGRAMS["nbody"]])
def test_the_entry_name_is_the_one_generate_gives(kernel):
    module = kernel.build_module()
    run_pipeline(module, DEFAULT_PIPELINE)
    assert generate(module, [kernel.key]).entries[kernel.key] == entry_name(kernel.key)
