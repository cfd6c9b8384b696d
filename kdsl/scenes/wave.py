"""wave: ``u_tt = c^2 Lap u`` on the unit square, zero on the boundary, at rest at t = 0.

Each sine mode of the initial state (``grid.MODES``) oscillates as ``cos(omega t)``,
``omega = c sqrt(-lambda)``, with ``lambda`` the discrete eigenvalue for the
reference (the semi-discrete solution) and the continuous one for ``pde_error``.
Theory (CFL): symplectic Euler and velocity Verlet (leapfrog) are stable for
``dt <= 2 / omega_max``, ``omega_max = c sqrt(rho) ~ 2 sqrt(2) c / h``, the 2D
CFL limit ``c dt / h <= 1 / sqrt(2)``; explicit Euler never (no damping); backward
Euler always. The energy is ``1/2 sum (v^2 + c^2 |grad u|^2) h^2``.
"""

import math
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes import grid
from kdsl.scenes.base import Scene


class Wave(Scene):
    """2D wave equation against its analytic solution (see the module docstring)."""

    name = "wave"
    summary = "2D wave equation, CFL limit c dt/h <= 1/sqrt(2), vs the analytic solution"
    order = 2
    integrators = ("velocity_verlet", "symplectic_euler", "explicit_euler", "rk4",
                   "backward_euler")  # fmt: skip
    defaults = {"grid": 32, "speed": 1.0, "jacobi_iters": 40}
    default_dt = 5e-3
    default_steps = 200

    def setup(self) -> None:
        self.grid_n = int(self.params["grid"])
        self.h = 1.0 / (self.grid_n + 1)

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        return grid.make_grid_kernels(wp, real)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        u0 = sum(a * grid.mode(self.grid_n, kx, ky) for kx, ky, a in grid.MODES)
        return u0, np.zeros_like(u0)

    def _lap(self, u: Any, s: float, out: Any) -> None:
        n = self.grid_n
        self.launch(self.k.laplacian, (n, n), [u, n, self.real(s / self.h**2), out])

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self._lap(x, self.params["speed"] ** 2, out)

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        self._lap(z, cx * self.params["speed"] ** 2, out)

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        value = -4.0 * cx * self.params["speed"] ** 2 / self.h**2
        self.launch(self.k.fill, self.n, [self.real(value), out])

    def _solution(self, t: float, eigenvalue: Any) -> np.ndarray:
        c, n = self.params["speed"], self.grid_n
        return sum(a * math.cos(c * math.sqrt(-eigenvalue(kx, ky)) * t) * grid.mode(n, kx, ky)
                   for kx, ky, a in grid.MODES)  # fmt: skip

    def picture(self, x: np.ndarray) -> Any:
        """The displacement as a colored height field (``kdsl scene run --render``)."""
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
        assert v is not None
        n, c = self.grid_n, self.params["speed"]
        u = np.pad(x.reshape(n, n), 1)
        grad2 = np.sum(np.diff(u, axis=0) ** 2) + np.sum(np.diff(u, axis=1) ** 2)
        return float(0.5 * (np.sum(v * v) * self.h**2 + c * c * grad2))

    def theory_dt_limit(self, integrator: str) -> float | None:
        omega_max = self.params["speed"] * math.sqrt(grid.spectral_radius(self.grid_n))
        return {"symplectic_euler": 2.0 / omega_max, "velocity_verlet": 2.0 / omega_max,
                "backward_euler": math.inf}.get(integrator)  # fmt: skip

    def cfl_dt_limit(self) -> float:
        """``h / (c sqrt(2))``, the textbook 2D CFL limit."""
        return self.h / (self.params["speed"] * math.sqrt(2.0))
