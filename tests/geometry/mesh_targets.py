"""What the mesh tests share: the backends they run on (interp, cpu, and cuda with a
GPU), the device of each, and central differences of a per-point loss."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

import kdsl as wp

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


def device_of(backend: str) -> str:
    """The device a backend's launches run on."""
    return "cuda" if backend == "cuda" else "cpu"


def central_differences(
    loss: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, h: float = 1e-3
) -> np.ndarray:
    """d loss[i] / d x0[i, k] for points ``x0`` (n, 3), by central differences (float64);
    ``loss`` maps points to one float per point."""
    fd = np.zeros(x0.shape, np.float64)
    for k in range(x0.shape[1]):
        dx = np.zeros_like(x0)
        dx[:, k] = h
        fd[:, k] = (loss(x0 + dx) - loss(x0 - dx)) / (2 * h)
    return fd
