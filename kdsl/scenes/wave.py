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

import numpy as np

from kdsl.scenes import grid


class Wave(grid.GridScene):
    """2D wave equation against its analytic solution (see the module docstring)."""

    name = "wave"
    summary = "2D wave equation, CFL limit c dt/h <= 1/sqrt(2), vs the analytic solution"
    order = 2
    integrators = ("velocity_verlet", "symplectic_euler", "explicit_euler", "rk4",
                   "backward_euler")  # fmt: skip
    defaults = {"grid": 32, "speed": 1.0, "jacobi_iters": 40}
    default_dt = 5e-3
    default_steps = 200

    def coefficient(self) -> float:
        return self.params["speed"] ** 2

    def mode_factor(self, eigenvalue: float, t: float) -> float:
        return math.cos(self.params["speed"] * math.sqrt(-eigenvalue) * t)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        u0 = self.initial_modes()
        return u0, np.zeros_like(u0)

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
