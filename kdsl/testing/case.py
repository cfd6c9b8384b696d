"""``Case``: one conformance case, declared as data.

A case names a kernel, a launch dimension, a generator of inputs (NumPy arrays and
scalars drawn from a seeded generator, in the dtypes the kernel takes) and a
reference written in NumPy float64 that returns the expected value of every
output array. Tolerances come from the output's dtype unless the case overrides
them; ``requires`` lists the backend capabilities the case needs.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

Inputs = dict[str, Any]

#: (rtol, atol) per output element kind and width; integers and bools compare exactly.
DEFAULT_TOL: dict[str, tuple[float, float]] = {
    "float16": (1e-2, 1e-2),
    "float32": (1e-5, 1e-6),
    "float64": (1e-12, 1e-12),
}


@dataclass(frozen=True)
class Case:
    """One conformance case. See the module docstring.

    ``kernel`` is a ``@kdsl.kernel`` object; ``make_inputs(rng)`` returns every
    kernel argument by name; ``reference(inputs)`` returns the expected contents
    of the output arrays named in ``outputs`` (float64 or exact integers).
    """

    name: str
    kernel: Any
    dim: int | tuple[int, ...]
    make_inputs: Callable[[np.random.Generator], Inputs]
    reference: Callable[[Inputs], Mapping[str, Any]]
    outputs: tuple[str, ...]
    requires: tuple[str, ...] = ()
    #: Overrides of the dtype tolerance: (rtol, atol).
    tol: tuple[float, float] | None = None
    #: When set, float outputs must be within this many units in the last place of
    #: the output's dtype (at the expected value) instead of (rtol, atol).
    ulps: int | None = None
    #: Seed of the generator passed to ``make_inputs``.
    seed: int = 1234

    def tolerance(self, dtype: np.dtype) -> tuple[float, float] | None:
        """(rtol, atol) for an output of ``dtype``; None means compare exactly."""
        if dtype.kind != "f":
            return None
        if self.tol is not None:
            return self.tol
        return DEFAULT_TOL[dtype.name]


def uniform(
    rng: np.random.Generator, shape: Any, lo: float, hi: float, dtype: Any = np.float32
) -> np.ndarray:
    """Floats drawn uniformly from [lo, hi)."""
    return rng.uniform(lo, hi, size=shape).astype(dtype)


def integers(
    rng: np.random.Generator, shape: Any, lo: int, hi: int, dtype: Any = np.int32
) -> np.ndarray:
    """Integers drawn uniformly from [lo, hi)."""
    return rng.integers(lo, hi, size=shape).astype(dtype)


def f64(x: Any) -> np.ndarray:
    """``x`` as a float64 array (the dtype every reference computes in)."""
    return np.asarray(x, dtype=np.float64)


@dataclass(frozen=True)
class GradCase:
    """A gradient conformance case: the kernel's adjoint against finite differences.

    ``make_inputs(rng)`` returns every kernel argument by name (float64 arrays for
    the differentiable ones); ``inputs`` names the arrays to differentiate with
    respect to and ``outputs`` the arrays whose gradients seed the backward pass.
    ``kdsl.autograd.gradcheck`` compares the Jacobians (central differences with
    step ``eps``) within ``tol`` = (rtol, atol).
    """

    name: str
    kernel: Any
    dim: int | tuple[int, ...]
    make_inputs: Callable[[np.random.Generator], Inputs]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    requires: tuple[str, ...] = ("fp64",)
    tol: tuple[float, float] = (1e-5, 1e-7)
    eps: float = 1e-6
    seed: int = 1234

