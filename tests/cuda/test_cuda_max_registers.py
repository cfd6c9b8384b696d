"""The kernel option ``cuda_max_registers`` (Warp 1.19's): the cuda backend declares the
kernel's entries ``__maxnreg__(N)`` instead of ``__launch_bounds__(256)`` and NVRTC caps
its registers (compile-only, no GPU needed; a launch on a GPU when one is present); the
other backends ignore it; a bad value is a ``KdslError``."""

from __future__ import annotations

import re

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError


def _saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


capped = wp.kernel(_saxpy, cuda_max_registers=32)
plain = wp.kernel(_saxpy)


def _unit(kernel) -> str:
    from kdsl.backends.cuda.backend import max_registers
    from kdsl.backends.cuda.lower import generate
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    return generate(m, [kernel.key], max_registers=max_registers(kernel.options)).text


def test_entries_declare_the_cap():
    unit = _unit(capped)
    assert "__maxnreg__(32)" in unit and "__launch_bounds__" not in unit
    assert "__launch_bounds__(256)" in _unit(plain) and "__maxnreg__" not in _unit(plain)


def test_nvrtc_caps_the_registers():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc

    ptx = nvrtc.compile_source(_unit(capped), "sm_90").ptx
    assert re.findall(r"\.maxnreg\s+(\d+)", ptx) and set(re.findall(r"\.maxnreg\s+(\d+)", ptx)) == {
        "32"
    }


@pytest.mark.parametrize("bad", [0, -4, 2.5, True, "64"])
def test_bad_values_are_refused(bad):
    from kdsl.backends.cuda.backend import max_registers

    with pytest.raises(KdslError, match="cuda_max_registers must be a positive int"):
        max_registers({"cuda_max_registers": bad})


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_other_backends_ignore_it(backend):
    x = wp.array(np.arange(4, dtype=np.float32))
    y = wp.array(np.ones(4, dtype=np.float32))
    wp.launch(capped, 4, [x, y, 2.0], backend=backend)
    np.testing.assert_array_equal(y.numpy(), 2.0 * np.arange(4) + 1.0)


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")
def test_launch_on_a_gpu():
    x = wp.array(np.arange(4, dtype=np.float32), device="cuda:0")
    y = wp.array(np.ones(4, dtype=np.float32), device="cuda:0")
    wp.launch(capped, 4, [x, y, 2.0], device="cuda:0")
    np.testing.assert_array_equal(y.numpy(), 2.0 * np.arange(4) + 1.0)
