"""What the 2D grid scenes (heat, wave) share: the 5-point Laplacian, its modes and
``GridScene``, their common base (``du = coefficient * Lap u`` and its references).

The unknowns are the ``n x n`` interior points of the unit square with spacing
``h = 1 / (n + 1)``, stored flat (``i * n + j``), zero on the boundary (Dirichlet).
``sin(k pi x) sin(l pi y)`` is an exact eigenvector of the discrete Laplacian with
eigenvalue ``-(4 / h^2) (sin^2(k pi h / 2) + sin^2(l pi h / 2))``, so the
semi-discrete (method of lines) solutions are closed forms: the references the grid
scenes compare against, isolating the time integrator's error from the grid's.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables.

import math
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.base import Scene

#: The modes (k, l, amplitude) of the initial condition.
MODES = ((1, 1, 1.0), (2, 3, 0.5))


@cache
def make_grid_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """``laplacian(u, n, s, out)``: ``out = s * (5-point sum)``; ``fill(value, out)``."""

    @wp.kernel(module="unique")
    def laplacian(u: wp.array(dtype=real), n: int, s: real, out: wp.array(dtype=real)):
        i, j = wp.tid()
        c = u[i * n + j]
        total = real(-4.0) * c
        if i > 0:
            total += u[(i - 1) * n + j]
        if i < n - 1:
            total += u[(i + 1) * n + j]
        if j > 0:
            total += u[i * n + j - 1]
        if j < n - 1:
            total += u[i * n + j + 1]
        out[i * n + j] = s * total

    @wp.kernel(module="unique")
    def fill(value: real, out: wp.array(dtype=real)):
        out[wp.tid()] = value

    return SimpleNamespace(laplacian=laplacian, fill=fill)


def grid_points(n: int, rows: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The interior points' x and y (flat, ``i * n + j``); only rows ``[first, end)`` of
    them when ``rows`` is given (a strip: the same values as those rows of the whole)."""
    h = 1.0 / (n + 1)
    x = np.arange(1, n + 1) * h
    gx, gy = np.meshgrid(x if rows is None else x[rows[0] : rows[1]], x, indexing="ij")
    return gx.ravel(), gy.ravel()


def mode(n: int, kx: int, ky: int, rows: tuple[int, int] | None = None) -> np.ndarray:
    """``sin(k pi x) sin(l pi y)`` on the interior points (of ``rows`` only, if given)."""
    gx, gy = grid_points(n, rows)
    return np.sin(kx * np.pi * gx) * np.sin(ky * np.pi * gy)


def discrete_eigenvalue(n: int, kx: int, ky: int) -> float:
    """The (negative) eigenvalue of the discrete Laplacian for mode ``(k, l)``."""
    h = 1.0 / (n + 1)
    return -(4.0 / h**2) * (
        math.sin(kx * math.pi * h / 2) ** 2 + math.sin(ky * math.pi * h / 2) ** 2
    )


def continuum_eigenvalue(kx: int, ky: int) -> float:
    """The eigenvalue ``-(k^2 + l^2) pi^2`` of the continuous Laplacian."""
    return -(kx * kx + ky * ky) * math.pi**2


def spectral_radius(n: int) -> float:
    """The largest ``|eigenvalue|`` of the discrete Laplacian (mode ``(n, n)``)."""
    return -discrete_eigenvalue(n, n, n)


class GridScene(Scene):
    """A scene whose right-hand side is ``coefficient() * Lap u`` on the ``grid x grid``
    interior points, started from ``MODES``; its references are mode sums whose time
    factors ``mode_factor`` gives (the heat equation's decay, the wave's oscillation)."""

    #: The rows ``[first, end)`` this scene holds (None: all; a strip sets its own).
    rows: tuple[int, int] | None = None

    def setup(self) -> None:
        self.grid_n = int(self.params["grid"])
        self.h = 1.0 / (self.grid_n + 1)

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        return make_grid_kernels(wp, real)

    def coefficient(self) -> float:
        """The factor of the Laplacian in the equation (``D``, ``c^2``)."""
        raise NotImplementedError

    def mode_factor(self, eigenvalue: float, t: float) -> float:
        """A mode's amplitude at ``t`` (1 at 0) for the Laplacian ``eigenvalue``."""
        raise NotImplementedError

    def initial_modes(self) -> np.ndarray:
        """The initial field: the sum of ``MODES``."""
        return sum(a * mode(self.grid_n, kx, ky, self.rows) for kx, ky, a in MODES)

    def _lap(self, u: Any, s: float, out: Any) -> None:
        n = self.grid_n
        self.launch(self.k.laplacian, (n, n), [u, n, self.real(s / self.h**2), out])

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self._lap(x, self.coefficient(), out)

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        self._lap(z, cx * self.coefficient(), out)

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        value = -4.0 * cx * self.coefficient() / self.h**2
        self.launch(self.k.fill, self.n, [self.real(value), out])

    def _solution(self, t: float, eigenvalue: Any) -> np.ndarray:
        n = self.grid_n
        return sum(a * self.mode_factor(eigenvalue(kx, ky), t) * mode(n, kx, ky, self.rows)
                   for kx, ky, a in MODES)  # fmt: skip

    def picture(self, x: np.ndarray) -> Any:
        """The field as a colored height field (``kdsl scene run --render``)."""
        from kdsl.scenes import render

        return render.height_field(x, render.height_scale(self))

    def reference(self, t: float) -> np.ndarray:
        return self._solution(t, lambda kx, ky: discrete_eigenvalue(self.grid_n, kx, ky))

    def pde_error(self) -> float:
        """The error against the continuous PDE's solution (time and grid together)."""
        x, _ = self.state()
        ref = self._solution(self.t, continuum_eigenvalue)
        return float(np.max(np.abs(x - ref)) / max(np.max(np.abs(ref)), 1e-300))
