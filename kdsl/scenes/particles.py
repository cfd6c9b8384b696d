"""particles: the seeds' ``integrate`` kernel, particles falling under gravity with drag.

``a = g - c v`` (linear drag ``c``, unit mass) has the closed form

    v(t) = v_inf + (v0 - v_inf) e^{-ct},   v_inf = g / c
    x(t) = x0 + v_inf t + (v0 - v_inf) (1 - e^{-ct}) / c

which is the reference. Each particle starts at its own position and velocity.
The symplectic Euler step is the seeds' fused ``integrate`` kernel (one launch, drag
added); the other integrators build on ``accel``. Theory: explicit and symplectic
Euler are stable for ``dt <= 2 / c``, RK4 for ``dt <= 2.785 / c``.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables
# (``real``, ``vec3``), which string annotations cannot reach.

import math
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.base import Scene
from kdsl.scenes.binding import kernel_types

#: RK4's stability interval on the negative real axis.
RK4_REAL_LIMIT = 2.785293563


@cache
def make_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """The particle kernels for float type ``real``."""
    vec3, Vec3Array, RealArray, _ = kernel_types(wp, real)

    @wp.kernel(module="unique")
    def integrate(
        x: Vec3Array, v: Vec3Array, f: Vec3Array, w: RealArray, gravity: vec3, drag: real, dt: real
    ):
        # The seeds' semi-implicit Euler step, with linear drag added.
        tid = wp.tid()
        x0 = x[tid]
        v0 = v[tid]
        f_ext = f[tid]
        inv_mass = w[tid]
        v1 = v0 + (f_ext * inv_mass + gravity - v0 * drag) * dt
        x1 = x0 + v1 * dt
        x[tid] = x1
        v[tid] = v1

    @wp.kernel(module="unique")
    def accel(v: Vec3Array, gravity: vec3, drag: real, a: Vec3Array):
        tid = wp.tid()
        a[tid] = gravity - v[tid] * drag

    @wp.kernel(module="unique")
    def drag_jvp(z: Vec3Array, cv: real, drag: real, out: Vec3Array):
        tid = wp.tid()
        out[tid] = z[tid] * (-cv * drag)

    @wp.kernel(module="unique")
    def drag_diag(cv: real, drag: real, out: RealArray):
        out[wp.tid()] = -cv * drag

    return SimpleNamespace(integrate=integrate, accel=accel, drag_jvp=drag_jvp,
                           drag_diag=drag_diag, vec3=vec3)  # fmt: skip


class Particles(Scene):
    """Particles under gravity with linear drag, against the closed form."""

    name = "particles"
    summary = "the seeds' integrate kernel: gravity with linear drag vs the closed form"
    order = 2
    integrators = ("symplectic_euler", "explicit_euler", "velocity_verlet", "rk4",
                   "backward_euler")  # fmt: skip
    defaults = {"count": 1024, "drag": 0.5, "gravity": -9.81, "jacobi_iters": 1}
    default_dt = 1e-2
    default_steps = 200
    velocity_dependent = True

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        k = make_kernels(wp, real)
        n = self.params["count"]
        self.g = np.array([0.0, self.params["gravity"], 0.0])
        self.gravity = k.vec3(*self.g)
        self.f = wp.zeros(n, dtype=k.vec3, device=self.device)
        self.w = wp.ones(n, dtype=real, device=self.device)
        return k

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.params["count"]
        i = np.arange(n, dtype=np.float64)
        x0 = np.stack([np.cos(i), 10.0 + np.sin(i), 0.01 * i], axis=1)
        v0 = np.stack([np.sin(2 * i), 5.0 * np.cos(i), np.ones(n)], axis=1)
        return x0, v0

    def step(self, dt: float) -> None:
        if self.integrator != "symplectic_euler":
            super().step(dt)
            return
        drag, h = self.real(self.params["drag"]), self.real(dt)
        self.launch(self.k.integrate, self.n, [self.x, self.v, self.f, self.w,
                                                self.gravity, drag, h])  # fmt: skip
        self.t += dt

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self.launch(self.k.accel, self.n, [v, self.gravity, self.real(self.params["drag"]), out])

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        drag = self.real(self.params["drag"])
        self.launch(self.k.drag_jvp, self.n, [z, self.real(cv), drag, out])

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        self.launch(self.k.drag_diag, self.n, [self.real(cv), self.real(self.params["drag"]), out])

    def reference(self, t: float) -> np.ndarray:
        c = self.params["drag"]
        x0, v0 = self.initial_state()
        v_inf = self.g / c
        return x0 + v_inf * t + (v0 - v_inf) * (-math.expm1(-c * t)) / c

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float:
        """Kinetic plus potential energy per unit mass, summed over the particles."""
        assert v is not None
        return float(0.5 * np.sum(v * v) - np.sum(x @ self.g))

    def stability_measure(self, x: np.ndarray, v: np.ndarray | None) -> float:
        """Kinetic energy: drag pulls every velocity toward ``g / c``, so it stays bounded."""
        assert v is not None
        return float(0.5 * np.sum(v * v))

    def theory_dt_limit(self, integrator: str) -> float | None:
        c = self.params["drag"]
        return {"explicit_euler": 2.0 / c, "symplectic_euler": 2.0 / c,
                "rk4": RK4_REAL_LIMIT / c, "backward_euler": math.inf}.get(integrator)  # fmt: skip
