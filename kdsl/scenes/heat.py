"""heat: ``u_t = D Lap u`` on the unit square, zero on the boundary.

The initial state is a sum of sine modes (``grid.MODES``); each decays as
``exp(D lambda t)``, with ``lambda`` the discrete Laplacian's eigenvalue for the
reference (the semi-discrete solution, so the error is the integrator's) and the
continuous one for ``pde_error`` (the grid's error too). Theory: explicit Euler is
stable for ``dt <= 2 / (D rho)`` with ``rho`` the Laplacian's spectral radius,
``~ 8 / h^2``: the textbook ``dt <= h^2 / (4 D)``; RK4 for ``dt <= 2.785 / (D rho)``;
backward Euler always. The "energy" is ``1/2 sum u^2 h^2``, which only decays.
"""

import numpy as np

from kdsl.scenes import grid
from kdsl.scenes.base import FIRST_ORDER_INTEGRATORS
from kdsl.scenes.particles import RK4_REAL_LIMIT


class Heat(grid.GridScene):
    """2D heat equation against its analytic solution (see the module docstring)."""

    name = "heat"
    summary = "2D heat equation, explicit limit dt <= h^2/(4D), vs the analytic solution"
    order = 1
    integrators = FIRST_ORDER_INTEGRATORS
    defaults = {"grid": 32, "diffusivity": 1.0, "jacobi_iters": 40}
    default_dt = 5e-5
    default_steps = 400

    def coefficient(self) -> float:
        return self.params["diffusivity"]

    def mode_factor(self, eigenvalue: float, t: float) -> float:
        return np.exp(self.params["diffusivity"] * eigenvalue * t)

    def initial_state(self) -> tuple[np.ndarray, None]:
        return self.initial_modes(), None

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float:
        return float(0.5 * np.sum(x * x) * self.h**2)

    def theory_dt_limit(self, integrator: str) -> float | None:
        rho = self.params["diffusivity"] * grid.spectral_radius(self.grid_n)
        return {"explicit_euler": 2.0 / rho, "rk4": RK4_REAL_LIMIT / rho,
                "backward_euler": float("inf")}.get(integrator)  # fmt: skip

    def textbook_dt_limit(self) -> float:
        """``h^2 / (4 D)``, the usual statement of the explicit limit."""
        return self.h**2 / (4.0 * self.params["diffusivity"])
