"""The ``block-cache`` pass: where it runs, its options, and that its mark changes nothing
on the backends that do not act on it (interp, cpu). The IR it marks is tested in
``tests/filecheck/block_cache.kir``; the tiled CUDA code in
``tests/cuda/test_cuda_block_cache.py``."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.registry import get_backend
from kdsl.compiler import lower
from kdsl.ir import types as T
from kdsl.passes import DEFAULT_PIPELINE, PassManager, get_pass
from kdsl.passes.block_cache import ATTR, element_bytes
from kdsl.testing.cases.programs import make_programs


def _nbody() -> wp.Kernel:
    """A fresh n-body kernel object (compiled on its first launch)."""
    return make_programs()["nbody"]


def _inputs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(n, 3)).astype(np.float32)
    mass = rng.uniform(0.5, 1.5, n).astype(np.float32)
    return pos, mass


def _run(kernel, backend: str, pos, mass, dim: int | None = None) -> np.ndarray:
    device = "cpu"
    acc = wp.zeros(len(pos), dtype=wp.vec3, device=device)
    args = [wp.array(pos, dtype=wp.vec3, device=device), wp.array(mass, device=device), acc, 0.01]
    wp.launch(kernel, dim=len(pos) if dim is None else dim, inputs=args, device=device,
              backend=backend)  # fmt: skip
    return acc.numpy()


def test_pass_is_in_the_cuda_pipeline_only():
    assert get_backend("cuda").pipeline.split(",")[-1] == "block-cache"
    for name in ("cpu", "interp"):
        assert "block-cache" not in get_backend(name).pipeline


@pytest.mark.parametrize("backend", ["interp", "cpu"])
@pytest.mark.parametrize("n, dim", [(1, 1), (37, 37), (300, 300), (300, 7)])
def test_marked_loop_runs_bit_identically(backend, n, dim, monkeypatch):
    """The same kernel through the backend's pipeline with and without block-cache:
    the mark is in the optimized IR, and the results agree bit for bit."""
    be = get_backend(backend)
    pos, mass = _inputs(n)
    plain = _run(_nbody(), backend, pos, mass, dim)
    monkeypatch.setattr(be, "pipeline", f"{DEFAULT_PIPELINE},block-cache")
    tiled_kernel = _nbody()
    assert f"{ATTR} = 256" in lower(be, tiled_kernel, "kir-opt")
    tiled = _run(tiled_kernel, backend, pos, mass, dim)
    np.testing.assert_array_equal(tiled.view(np.uint32), plain.view(np.uint32))
    assert np.isfinite(plain[:dim]).all() and (plain[dim:] == 0).all()


def test_options_are_checked():
    cls = get_pass("block-cache")
    with pytest.raises(ValueError, match="tile and max_bytes must be positive"):
        cls(tile=0)
    with pytest.raises(ValueError, match="tile and max_bytes must be positive"):
        PassManager("block-cache{max_bytes=-1}")
    with pytest.raises(ValueError, match="has no option 'size'"):
        PassManager("block-cache{size=4}")


@pytest.mark.parametrize(
    "t, size",
    [(T.F32, 4), (T.F64, 8), (T.I8, 1), (T.I64, 8), (T.BOOL, None), (T.F16, None),
     (T.VectorType(3, T.F32), 12), (T.MatrixType(4, 4, T.F64), 128),
     (T.VectorType(2, T.F16), None)],
)  # fmt: skip
def test_element_bytes(t, size):
    assert element_bytes(t) == size
