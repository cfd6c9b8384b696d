"""stiff_odes: many independent stiff ODE systems, one per thread.

Even threads integrate Van der Pol's oscillator with ``mu`` (default 1e3) in its
relaxation scaling (``t`` measured in units of ``mu``, ``eps = 1 / mu^2``):

    y1' = y2,   y2' = ((1 - y1^2) y2 - y1) / eps

started on the slow manifold (``y1`` in [1.8, 2.2], ``y2 = y1 / (1 - y1^2)``), whose
Jacobian has an eigenvalue near ``-(y1^2 - 1) / eps ~ -3e6``. Odd threads integrate
Robertson's chemical kinetics (``k1`` in [0.04, 0.05], ``k2 = 3e7``, ``k3 = 1e4``):

    y1' = -k1 y1 + k3 y2 y3,   y2' = k1 y1 - k3 y2 y3 - k2 y2^2,   y3' = k2 y2^2

Each state is a ``vec3`` (Van der Pol leaves the third component at zero). The
reference is a float64 run of the 3-stage Radau IIA method (order 5, L-stable) on the
host, over graded steps (``1e-7`` growing to ``REF_MAX_STEP``), with Newton solved
to round-off: halving its steps changes it by less than 1e-10 (a test checks).

``backward_euler`` here is not the generic one-Newton-step-plus-Jacobi of
``kdsl.scenes.integrators``: each thread runs ``newton_iters`` full Newton iterations
on its own 3x3 system, solved directly (Cramer's rule). The systems are tiny and
dense and their Jacobians are far from diagonally dominant (Van der Pol's
``|J_21| h`` dwarfs the diagonal at the step sizes that make an implicit method
worth having), so Jacobi would diverge; a direct solve per thread is what a stiff
ODE solver does. Explicit Euler and RK4 are stable only for
``dt <~ 2 / 3.8e6 = 5e-7`` (``theory_dt_limit``, from the initial Jacobians).
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables.

import math
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.base import FIRST_ORDER_INTEGRATORS, Scene
from kdsl.scenes.binding import kernel_types

#: Robertson's fast rate constants.
K2, K3 = 3.0e7, 1.0e4
#: The reference's largest step (Radau IIA, order 5).
REF_MAX_STEP = 2e-4
#: The reference's first step and growth factor (graded through the initial layers).
REF_FIRST_STEP, REF_GROWTH = 1e-7, 1.25
#: RK4's stability interval on the negative real axis.
RK4_REAL_LIMIT = 2.785293563


@cache
def make_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """The stiff ODE kernels for float type ``real``."""
    vec3, Vec3Array, RealArray, IntArray = kernel_types(wp, real)

    @wp.kernel(module="unique")
    def stiff_rhs(y: Vec3Array, kind: IntArray, k1: RealArray, inv_eps: real, out: Vec3Array):
        i = wp.tid()
        s = y[i]
        f = vec3(real(0.0), real(0.0), real(0.0))
        if kind[i] == 0:
            f = vec3(s[1], ((real(1.0) - s[0] * s[0]) * s[1] - s[0]) * inv_eps, real(0.0))
        else:
            a = k1[i] * s[0]
            b = real(K3) * s[1] * s[2]
            c = real(K2) * s[1] * s[1]
            f = vec3(b - a, a - b - c, c)
        out[i] = f

    @wp.kernel(module="unique")
    def stiff_backward_euler(
        y: Vec3Array, kind: IntArray, k1: RealArray, inv_eps: real, h: real, newton_iters: int
    ):
        # Solve z - y - h f(z) = 0 by Newton from z = y; each iteration solves
        # (I - h J(z)) dz = -(z - y - h f(z)) by Cramer's rule with the columns of I - hJ.
        i = wp.tid()
        y0 = y[i]
        z = y0
        one = real(1.0)
        zero = real(0.0)
        for _ in range(newton_iters):
            f = vec3(zero, zero, zero)
            c0 = vec3(one, zero, zero)
            c1 = vec3(zero, one, zero)
            c2 = vec3(zero, zero, one)
            if kind[i] == 0:
                f = vec3(z[1], ((one - z[0] * z[0]) * z[1] - z[0]) * inv_eps, zero)
                # J = [[0, 1, 0], [(-2 y1 y2 - 1) / eps, (1 - y1^2) / eps, 0], [0, 0, 0]]
                c0 = vec3(one, h * (real(2.0) * z[0] * z[1] + one) * inv_eps, zero)
                c1 = vec3(-h, one - h * (one - z[0] * z[0]) * inv_eps, zero)
            else:
                a = k1[i]
                b = real(K3) * z[1] * z[2]
                c = real(K2) * z[1] * z[1]
                f = vec3(b - a * z[0], a * z[0] - b - c, c)
                d2 = real(K3) * z[2]
                d3 = real(K3) * z[1]
                e2 = real(2.0) * real(K2) * z[1]
                # J columns: d/dy1 = (-a, a, 0); d/dy2 = (d2, -d2 - e2, e2); d/dy3 = (d3, -d3, 0)
                c0 = vec3(one + h * a, -h * a, zero)
                c1 = vec3(-h * d2, one + h * (d2 + e2), -h * e2)
                c2 = vec3(-h * d3, h * d3, one)
            g = y0 + h * f - z
            c12 = wp.cross(c1, c2)
            det = wp.dot(c0, c12)
            dz = vec3(wp.dot(g, c12), wp.dot(c0, wp.cross(g, c2)), wp.dot(c0, wp.cross(c1, g)))
            z = z + dz / det
        y[i] = z

    return SimpleNamespace(stiff_rhs=stiff_rhs, stiff_backward_euler=stiff_backward_euler)


# --------------------------------------------------------------------------- host side


def host_rhs(y: np.ndarray, kind: np.ndarray, k1: np.ndarray, inv_eps: float) -> np.ndarray:
    """``f(y)`` for every system (float64, vectorized)."""
    f = np.zeros_like(y)
    v, r = kind == 0, kind == 1
    y1, y2 = y[v, 0], y[v, 1]
    f[v, 0] = y2
    f[v, 1] = ((1.0 - y1 * y1) * y2 - y1) * inv_eps
    a = k1[r] * y[r, 0]
    b = K3 * y[r, 1] * y[r, 2]
    c = K2 * y[r, 1] ** 2
    f[r] = np.stack([b - a, a - b - c, c], axis=1)
    return f


def host_jacobian(y: np.ndarray, kind: np.ndarray, k1: np.ndarray, inv_eps: float) -> np.ndarray:
    """``df/dy`` for every system, ``(n, 3, 3)`` float64."""
    jac = np.zeros((len(y), 3, 3))
    v, r = kind == 0, kind == 1
    y1, y2 = y[v, 0], y[v, 1]
    jac[v, 0, 1] = 1.0
    jac[v, 1, 0] = (-2.0 * y1 * y2 - 1.0) * inv_eps
    jac[v, 1, 1] = (1.0 - y1 * y1) * inv_eps
    a, s2, s3 = k1[r], y[r, 1], y[r, 2]
    jac[r, 0, 0], jac[r, 0, 1], jac[r, 0, 2] = -a, K3 * s3, K3 * s2
    jac[r, 1, 0], jac[r, 1, 1], jac[r, 1, 2] = a, -K3 * s3 - 2 * K2 * s2, -K3 * s2
    jac[r, 2, 1] = 2 * K2 * s2
    return jac


_S6 = math.sqrt(6.0)
#: Radau IIA (3 stages, order 5): the Butcher matrix (its last row is b: stiffly accurate).
RADAU_A = np.array([
    [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
    [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
    [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9],
])  # fmt: skip


def radau_reference(y0: np.ndarray, t: float, f: Any, jac: Any,
                    max_step: float = REF_MAX_STEP) -> np.ndarray:  # fmt: skip
    """``y(t)`` by Radau IIA over graded steps, Newton to round-off, every system at once."""
    y = y0.copy()
    n, d = y.shape
    time, h = 0.0, REF_FIRST_STEP
    eye = np.eye(3 * d)
    while time < t:
        h = min(h, t - time)
        # Newton on the stage increments Z (n, 3, d): Z = h A f(y + Z), with J at y.
        big = eye[None] - h * np.einsum("ab,nij->naibj", RADAU_A, jac(y)).reshape(n, 3 * d, 3 * d)
        z = np.zeros((n, 3, d))
        for _ in range(50):
            fz = np.stack([f(y + z[:, s]) for s in range(3)], axis=1)
            res = z - h * np.einsum("ab,nbi->nai", RADAU_A, fz)
            dz = np.linalg.solve(big, -res.reshape(n, 3 * d, 1)).reshape(n, 3, d)
            z += dz
            if np.max(np.abs(dz)) <= 1e-15 * max(1.0, float(np.max(np.abs(y)))):
                break
        y = y + z[:, 2]
        time += h
        h = min(h * REF_GROWTH, max_step)
    return y


#: Reference results shared by every scene with the same parameters: (key, t) -> y.
_REFERENCES: dict[tuple, np.ndarray] = {}


class StiffOdes(Scene):
    """Van der Pol (mu = 1e3) and Robertson systems, one per thread (see the module doc)."""

    name = "stiff_odes"
    summary = "Van der Pol (mu=1e3) and Robertson kinetics, one stiff system per thread"
    order = 1
    integrators = ("backward_euler", "explicit_euler", "rk4")
    defaults = {"count": 64, "mu": 1000.0, "newton_iters": 6}
    default_dt = 1e-3
    default_steps = 400
    error_what = "max over (system kind, component) of max |y - y_ref| / max |y_ref|"
    assert set(integrators) == set(FIRST_ORDER_INTEGRATORS)

    def setup(self) -> None:
        n = self.int_param("count", 2, "one of each system")
        i = np.arange(n)
        self.kind = (i % 2).astype(np.int32)
        frac = (i // 2) / max(1, (n - 1) // 2)
        self.y1_0 = 1.8 + 0.4 * frac
        self.k1 = 0.04 + 0.01 * frac
        self.inv_eps = float(self.params["mu"]) ** 2

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        self.kind_arr = wp.array(self.kind, dtype=int, device=self.device)
        self.k1_arr = wp.array(self.k1, dtype=real, device=self.device)
        return make_kernels(wp, real)

    def initial_state(self) -> tuple[np.ndarray, None]:
        y = np.zeros((len(self.kind), 3))
        v = self.kind == 0
        y1 = self.y1_0[v]
        y[v, 0], y[v, 1] = y1, y1 / (1.0 - y1 * y1)  # on the slow manifold
        y[~v, 0] = 1.0
        return y, None

    def step(self, dt: float) -> None:
        if self.integrator != "backward_euler":
            super().step(dt)
            return
        self.launch(self.k.stiff_backward_euler, self.n,
                    [self.x, self.kind_arr, self.k1_arr, self.real(self.inv_eps), self.real(dt),
                     int(self.params["newton_iters"])])  # fmt: skip
        self.t += dt

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self.launch(self.k.stiff_rhs, self.n,
                    [x, self.kind_arr, self.k1_arr, self.real(self.inv_eps), out])  # fmt: skip

    def reference(self, t: float, max_step: float = REF_MAX_STEP) -> np.ndarray:
        key = (int(self.params["count"]), float(self.params["mu"]), round(t, 15), max_step)
        ref = _REFERENCES.get(key)
        if ref is None:
            args = (self.kind, self.k1, self.inv_eps)
            ref = radau_reference(self.initial_state()[0], t, lambda y: host_rhs(y, *args),
                                  lambda y: host_jacobian(y, *args), max_step)  # fmt: skip
            _REFERENCES[key] = ref
        return ref

    def _errors(self) -> dict[str, float]:
        """Per system kind, the worst component's ``max |y - y_ref| / max |y_ref|``."""
        x, _ = self.state()
        ref = self.reference(self.t)
        out = {}
        for kind, label, comps in ((0, "van der pol", (0, 1)), (1, "robertson", (0, 1, 2))):
            rows = self.kind == kind
            worst = 0.0
            for c in comps:
                scale = max(float(np.max(np.abs(ref[rows, c]))), 1e-300)
                err = float(np.max(np.abs(x[rows, c] - ref[rows, c]))) / scale
                worst = max(worst, err if math.isfinite(err) else math.inf)
            out[label] = worst
        return out

    def error(self) -> float:
        return max(self._errors().values())

    def extra_errors(self) -> dict[str, float]:
        """The error of each system kind apart (``error`` is the larger)."""
        return {f"{k} error": v for k, v in self._errors().items()}

    def theory_dt_limit(self, integrator: str) -> float | None:
        if integrator == "backward_euler":
            return math.inf
        limit = {"explicit_euler": 2.0, "rk4": RK4_REAL_LIMIT}.get(integrator)
        if limit is None:
            return None
        y0, _ = self.initial_state()
        mu = np.linalg.eigvals(host_jacobian(y0, self.kind, self.k1, self.inv_eps)).ravel()
        mu = mu[mu.real < 0]  # the slow manifold's own (mild) growth is the physics
        # Explicit Euler on y' = mu y: |1 + h mu| <= 1, i.e. h <= -2 Re(mu) / |mu|^2 (RK4:
        # the same along the real axis, scaled by its interval, for these real eigenvalues).
        return float(np.min(-limit * mu.real / np.abs(mu) ** 2))
