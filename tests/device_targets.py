"""The targets tests run a kernel on, as ``(device, backend)`` parameters: the
interpreter, the cpu backend and cuda (skipped without a GPU)."""

import pytest

import kdsl as wp

TARGETS = [
    pytest.param("cpu", "interp", id="interp"),
    pytest.param("cpu", None, id="cpu"),
    pytest.param(
        "cuda:0", None, id="cuda",
        marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU"),
    ),
]  # fmt: skip
