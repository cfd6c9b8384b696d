"""heat: ``u_t = D Lap u`` on the unit square, zero on the boundary.

The initial state is a sum of sine modes (``grid.MODES``); each decays as
``exp(D lambda t)``, with ``lambda`` the discrete Laplacian's eigenvalue for the
reference (the semi-discrete solution, so the error is the integrator's) and the
continuous one for ``pde_error`` (the grid's error too). Theory: explicit Euler is
stable for ``dt <= 2 / (D rho)`` with ``rho`` the Laplacian's spectral radius,
``~ 8 / h^2``: the textbook ``dt <= h^2 / (4 D)``; RK4 for ``dt <= 2.785 / (D rho)``;
backward Euler always. The "energy" is ``1/2 sum u^2 h^2``, which only decays.
"""

from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes import grid
from kdsl.scenes.base import FIRST_ORDER_INTEGRATORS, Scene
from kdsl.scenes.particles import RK4_REAL_LIMIT


class Heat(Scene):
    """2D heat equation against its analytic solution (see the module docstring)."""

    name = "heat"
    summary = "2D heat equation, explicit limit dt <= h^2/(4D), vs the analytic solution"
    order = 1
    integrators = FIRST_ORDER_INTEGRATORS
    defaults = {"grid": 32, "diffusivity": 1.0, "jacobi_iters": 40}
    default_dt = 5e-5
    default_steps = 400

    def setup(self) -> None:
        self.grid_n = int(self.params["grid"])
        self.h = 1.0 / (self.grid_n + 1)

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        return grid.make_grid_kernels(wp, real)

    def initial_state(self) -> tuple[np.ndarray, None]:
        return sum(a * grid.mode(self.grid_n, kx, ky) for kx, ky, a in grid.MODES), None

    def _lap(self, u: Any, s: float, out: Any) -> None:
        n = self.grid_n
        self.launch(self.k.laplacian, (n, n), [u, n, self.real(s / self.h**2), out])

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self._lap(x, self.params["diffusivity"], out)

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        self._lap(z, cx * self.params["diffusivity"], out)

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        value = -4.0 * cx * self.params["diffusivity"] / self.h**2
        self.launch(self.k.fill, self.n, [self.real(value), out])

    def _solution(self, t: float, eigenvalue: Any) -> np.ndarray:
        d, n = self.params["diffusivity"], self.grid_n
        return sum(a * np.exp(d * eigenvalue(kx, ky) * t) * grid.mode(n, kx, ky)
                   for kx, ky, a in grid.MODES)  # fmt: skip

    def picture(self, x: np.ndarray) -> Any:
        """The temperature as a colored height field (``kdsl scene run --render``)."""
        from kdsl.scenes import render

        return render.height_field(x, render.height_scale(self))

    def reference(self, t: float) -> np.ndarray:
        return self._solution(t, lambda kx, ky: grid.discrete_eigenvalue(self.grid_n, kx, ky))

    def pde_error(self) -> float:
        """The error against the continuous PDE's solution (time and grid together)."""
        x, _ = self.state()
        ref = self._solution(self.t, grid.continuum_eigenvalue)
        return float(np.max(np.abs(x - ref)) / max(np.max(np.abs(ref)), 1e-300))

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float:
        return float(0.5 * np.sum(x * x) * self.h**2)

    def theory_dt_limit(self, integrator: str) -> float | None:
        rho = self.params["diffusivity"] * grid.spectral_radius(self.grid_n)
        return {"explicit_euler": 2.0 / rho, "rk4": RK4_REAL_LIMIT / rho,
                "backward_euler": float("inf")}.get(integrator)  # fmt: skip

    def textbook_dt_limit(self) -> float:
        """``h^2 / (4 D)``, the usual statement of the explicit limit."""
        return self.h**2 / (4.0 * self.params["diffusivity"])
