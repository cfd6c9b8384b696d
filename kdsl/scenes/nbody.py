"""nbody: gravitational n-body, all pairs, with Plummer softening.

``a_i = G sum_j m_j (x_j - x_i) / (|x_j - x_i|^2 + eps^2)^{3/2}``, one thread per
body looping over all bodies (the seeds' n-body kernel). Bodies start in a
random, seeded cloud of radius ``scale`` on near-circular orbits about the centre of
mass, with zero total momentum; body masses alternate 1 and ``mass_ratio``
(normalized to a total of 1). ``G`` is ``scale^3`` so the motion in units of
``scale`` is the same at every scale: ``scale`` from 1e-6 to 1e6 only probes the
float types' range. ``offset`` moves the whole cloud away from the origin
(``x_j - x_i`` then cancels: the float16/float32 cancellation case), and
``close=d`` puts body 1 at distance ``d * scale`` from body 0 (near-coincident
particles, where only the softening keeps the force finite).

The reference is a float64 small-step RK4 run of the same file
(``kdsl.scenes.reference``). ``error()`` is the relative energy error against the
reference's energy; ``extra_errors()`` adds the momentum error (``|P - P_ref|`` over
``sum m |v|``) and the position error.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables.

import math
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.base import Scene
from kdsl.scenes.binding import kernel_types
from kdsl.scenes.reference import small_step_reference


@cache
def make_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """The n-body kernels for float type ``real``."""
    vec3, Vec3Array, RealArray, _ = kernel_types(wp, real)

    @wp.func
    def softened_inv_r(d: vec3, eps2: real) -> real:
        # 1 / sqrt(|d|^2 + eps2): the softening keeps close encounters finite.
        return real(1.0) / wp.sqrt(wp.dot(d, d) + eps2)

    @wp.kernel(module="unique")
    def gravity_accel(x: Vec3Array, m: RealArray, g: real, eps2: real, out: Vec3Array):
        i = wp.tid()
        xi = x[i]
        a = vec3(real(0.0), real(0.0), real(0.0))
        for j in range(x.shape[0]):
            d = x[j] - xi
            inv_r = softened_inv_r(d, eps2)
            a = a + d * (g * m[j] * inv_r * inv_r * inv_r)
        out[i] = a

    @wp.kernel(module="unique")
    def gravity_jvp(
        x: Vec3Array, z: Vec3Array, m: RealArray, g: real, eps2: real, cx: real, out: Vec3Array
    ):
        # d a_i / d x_j = G m_j (I / r^3 - 3 d d^T / r^5): out_i = cx sum_j T_ij (z_j - z_i).
        i = wp.tid()
        xi = x[i]
        zi = z[i]
        total = vec3(real(0.0), real(0.0), real(0.0))
        for j in range(x.shape[0]):
            d = x[j] - xi
            inv_r = softened_inv_r(d, eps2)
            inv_r3 = inv_r * inv_r * inv_r
            dz = z[j] - zi
            total = total + (dz - d * (real(3.0) * wp.dot(d, dz) * inv_r * inv_r)) * (
                g * m[j] * inv_r3
            )
        out[i] = total * cx

    @wp.kernel(module="unique")
    def gravity_diag(x: Vec3Array, m: RealArray, g: real, eps2: real, cx: real, out: RealArray):
        # Gershgorin-safe: each tidal block's norm is at most 2 G m_j / r^3.
        i = wp.tid()
        xi = x[i]
        total = real(0.0)
        for j in range(x.shape[0]):
            inv_r = softened_inv_r(x[j] - xi, eps2)
            if j != i:
                total = total + real(2.0) * g * m[j] * inv_r * inv_r * inv_r
        out[i] = -cx * total

    return SimpleNamespace(gravity_accel=gravity_accel, gravity_jvp=gravity_jvp,
                           gravity_diag=gravity_diag)  # fmt: skip


class NBody(Scene):
    """Gravitational n-body against a float64 small-step reference (see the module doc)."""

    name = "nbody"
    summary = "gravitational n-body (all pairs, softened): energy and momentum errors"
    order = 2
    integrators = ("velocity_verlet", "symplectic_euler", "explicit_euler", "rk4",
                   "backward_euler")  # fmt: skip
    defaults = {"count": 64, "softening": 0.05, "mass_ratio": 1.0, "scale": 1.0, "offset": 0.0,
                "close": 0.0, "seed": 1, "jacobi_iters": 20}  # fmt: skip
    default_dt = 1e-3
    default_steps = 500
    error_what = "|E - E_ref| / |E_ref| (energy against the float64 small-step reference)"

    def setup(self) -> None:
        p = self.params
        n = self.int_param("count", 2)
        L = float(p["scale"])
        rng = np.random.default_rng(int(p["seed"]))
        m = np.where(np.arange(n) % 2 == 0, 1.0, float(p["mass_ratio"]))
        self.m = m / m.sum()
        pos = rng.normal(size=(n, 3))
        pos *= (rng.uniform(0.2, 1.0, size=n) / np.linalg.norm(pos, axis=1))[:, None]
        if p["close"]:
            pos[1] = pos[0] + np.array([p["close"], 0.0, 0.0])
        pos -= self.m @ pos
        # Near-circular orbits about the z axis through the centre of mass (G = 1 in
        # units of scale), then zero total momentum.
        r = np.linalg.norm(pos[:, :2], axis=1) + 1e-3
        enclosed = np.array([self.m[np.linalg.norm(pos, axis=1) <= np.linalg.norm(q)].sum()
                             for q in pos])  # fmt: skip
        speed = np.sqrt(enclosed / np.sqrt(r * r + p["softening"] ** 2))
        vel = np.stack([-pos[:, 1], pos[:, 0], np.zeros(n)], axis=1) / r[:, None] * speed[:, None]
        vel -= self.m @ vel
        self.x0 = (pos + p["offset"]) * L
        self.v0 = vel * L  # time is unchanged by scale: G = scale^3
        self.G = L**3
        self.eps2 = (p["softening"] * L) ** 2

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        self.m_arr = wp.array(self.m, dtype=real, device=self.device)
        return make_kernels(wp, real)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x0.copy(), self.v0.copy()

    def _consts(self) -> list[Any]:
        return [self.m_arr, self.real(self.G), self.real(self.eps2)]

    def step(self, dt: float) -> None:
        self.last_dt = dt
        super().step(dt)

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self.launch(self.k.gravity_accel, self.n, [x, *self._consts(), out])

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        self.launch(self.k.gravity_jvp, self.n, [x, z, *self._consts(), self.real(cx), out])

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        self.launch(self.k.gravity_diag, self.n, [x, *self._consts(), self.real(cx), out])

    def omega_max(self) -> float:
        """The fastest frequency's bound: ``sqrt(2 G M / eps^3)`` (the softened core)."""
        return math.sqrt(2.0 * self.G / self.eps2**1.5)

    def reference(self, t: float) -> np.ndarray:
        return small_step_reference(self, t, getattr(self, "last_dt", self.default_dt))

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float:
        """Kinetic plus softened potential energy (float64, host)."""
        assert v is not None
        d = x[None] - x[:, None]
        r = np.sqrt(np.sum(d * d, axis=2) + self.eps2)
        pair = self.m[:, None] * self.m[None] / r
        np.fill_diagonal(pair, 0.0)
        return float(0.5 * np.sum(self.m[:, None] * v * v) - 0.5 * self.G * np.sum(pair))

    def error(self) -> float:
        x, v = self.state()
        e_ref = self.energy(*self.reference_state(self.t))
        e = self.energy(x, v)
        err = abs(e - e_ref) / max(abs(e_ref), 1e-300)
        return err if math.isfinite(err) else math.inf

    def reference_state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The reference's ``(x, v)`` at ``t``."""
        from kdsl.scenes.reference import small_step_reference_state

        return small_step_reference_state(self, t, getattr(self, "last_dt", self.default_dt))

    def extra_errors(self) -> dict[str, float]:
        """The momentum error (over ``sum m |v|``) and the position error."""
        x, v = self.state()
        x_ref, v_ref = self.reference_state(self.t)
        p, p_ref = self.m @ v, self.m @ v_ref
        scale = float(np.sum(self.m * np.linalg.norm(v_ref, axis=1)))
        centred = x_ref - self.params["offset"] * self.params["scale"]
        pos = float(np.max(np.abs(x - x_ref)) / max(float(np.max(np.abs(centred))), 1e-300))
        return {"momentum error": float(np.max(np.abs(p - p_ref))) / max(scale, 1e-300),
                "position error": pos}  # fmt: skip

    def theory_dt_limit(self, integrator: str) -> float | None:
        return math.inf if integrator == "backward_euler" else None
