"""chain: a 1D spring chain between two walls, masses alternating 1 and ``mass_ratio``.

``m_i u_i'' = k (u_{i-1} - 2 u_i + u_{i+1}) - c m_i u_i'`` with ``u = 0`` at the walls:
the classic extreme case for explicit integrators, since the light masses set the
fastest mode ``omega_max`` and so the time step, while the heavy ones set the time
scale of the motion. Mass ratios from 1 to 1e6 make it stiff. ``count=1`` is a single
mass on two springs, the linear oscillator ``omega^2 = 2k/m``.

The reference is exact: the modes of ``M^-1 K`` (by a symmetric eigendecomposition
of ``M^-1/2 K M^-1/2`` in float64), each a damped oscillator in closed form.
Theory (per mode ``mu`` of ``[[0, 1], [-lambda, -c]]``): explicit Euler is stable
for ``dt <= -2 Re(mu) / |mu|^2`` (never when ``c = 0``); symplectic Euler and
velocity Verlet for ``dt <= 2 / omega_max`` when ``c = 0``.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables.

import math
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.base import Scene
from kdsl.scenes.binding import kernel_types


@cache
def make_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """The chain kernels for float type ``real``."""
    RealArray = kernel_types(wp, real).RealArray

    @wp.kernel(module="unique")
    def spring_jvp(
        u: RealArray,
        v: RealArray,
        inv_m: RealArray,
        k: real,
        c: real,
        cx: real,
        cv: real,
        out: RealArray,
    ):
        # out = cx * (M^-1 K-form applied to u) - cv * c * v: the spring forces are
        # linear, so the acceleration and its Jacobian product are one kernel.
        i = wp.tid()
        n = u.shape[0]
        left = real(0.0)
        right = real(0.0)
        if i > 0:
            left = u[i - 1]
        if i < n - 1:
            right = u[i + 1]
        out[i] = cx * k * inv_m[i] * (left - real(2.0) * u[i] + right) - cv * c * v[i]

    @wp.kernel(module="unique")
    def spring_diag(inv_m: RealArray, k: real, c: real, cx: real, cv: real, out: RealArray):
        i = wp.tid()
        out[i] = -cx * real(2.0) * k * inv_m[i] - cv * c

    return SimpleNamespace(spring_jvp=spring_jvp, spring_diag=spring_diag)


class Chain(Scene):
    """A spring chain with alternating masses (see the module docstring)."""

    name = "chain"
    summary = "1D spring chain between walls, mass ratios 1 to 1e6 (stiff for explicit steps)"
    order = 2
    defaults = {"count": 16, "stiffness": 100.0, "mass_ratio": 1.0, "damping": 0.0,
                "amplitude": 0.1, "jacobi_iters": 40}  # fmt: skip
    default_dt = 1e-3
    default_steps = 1000

    def setup(self) -> None:
        p = self.params
        n = int(p["count"])
        self.masses = np.where(np.arange(n) % 2 == 0, 1.0, float(p["mass_ratio"]))
        stiff = np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)
        s = 1.0 / np.sqrt(self.masses)
        # M^-1/2 K M^-1/2: symmetric, with the eigenvalues (omega^2) of M^-1 K.
        self.lam, self.modes = np.linalg.eigh(p["stiffness"] * stiff * s[:, None] * s[None, :])
        self.scale = s
        self.velocity_dependent = p["damping"] != 0.0

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        self.inv_m = wp.array(1.0 / self.masses, dtype=real, device=self.device)
        return make_kernels(wp, real)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        n = int(self.params["count"])
        u0 = self.params["amplitude"] * np.sin(np.pi * np.arange(1, n + 1) / (n + 1))
        if n > 2:
            u0[n // 2] += self.params["amplitude"]  # a kink excites the fast modes too
        return u0, np.zeros(n)

    def _consts(self, cx: float, cv: float) -> list[Any]:
        r, p = self.real, self.params
        return [r(p["stiffness"]), r(p["damping"]), r(cx), r(cv)]

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self.launch(self.k.spring_jvp, self.n, [x, v, self.inv_m, *self._consts(1.0, 1.0), out])

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        self.launch(self.k.spring_jvp, self.n, [z, z, self.inv_m, *self._consts(cx, cv), out])

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        self.launch(self.k.spring_diag, self.n, [self.inv_m, *self._consts(cx, cv), out])

    def reference(self, t: float) -> np.ndarray:
        u0, v0 = self.initial_state()
        c = self.params["damping"]
        # Modal coordinates q = Q^T M^1/2 u; each q'' + c q' + lambda q = 0.
        q0 = self.modes.T @ (u0 / self.scale)
        p0 = self.modes.T @ (v0 / self.scale)
        wd = np.sqrt((self.lam - 0.25 * c * c).astype(complex))
        decay = np.exp(-0.5 * c * t)
        with np.errstate(invalid="ignore", divide="ignore"):
            sinc = np.where(np.abs(wd) > 0, np.sin(wd * t) / np.where(wd == 0, 1, wd), t)
        q = decay * (q0 * np.cos(wd * t) + (p0 + 0.5 * c * q0) * sinc)
        return (self.modes @ q.real) * self.scale

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float:
        assert v is not None
        stretch = np.diff(np.concatenate([[0.0], x, [0.0]]))
        return float(0.5 * np.sum(self.masses * v * v)
                     + 0.5 * self.params["stiffness"] * np.sum(stretch**2))  # fmt: skip

    def theory_dt_limit(self, integrator: str) -> float | None:
        c = self.params["damping"]
        if integrator == "backward_euler":
            return math.inf
        if integrator == "explicit_euler":
            mu = -0.5 * c + np.sqrt((0.25 * c * c - self.lam).astype(complex))
            mu = np.concatenate([mu, -0.5 * c - np.sqrt((0.25 * c * c - self.lam).astype(complex))])
            return float(np.min(-2.0 * mu.real / np.abs(mu) ** 2))
        if integrator in ("symplectic_euler", "velocity_verlet") and c == 0.0:
            return 2.0 / math.sqrt(float(np.max(self.lam)))
        return None
