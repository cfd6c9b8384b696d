"""cloth: a mass-spring cloth pinned at two corners, falling onto a sphere.

A ``grid x grid`` sheet of particles (side ``size``, total ``mass``) lies flat at
``y = 0``; the two corners of its first row are pinned. Each particle is joined to
its 8 neighbours (structural and shear springs, stiffness ``stiffness`` from 1e2 to
1e6, optional dashpots ``damping``), falls under gravity and meets a sphere of radius
``radius`` whose top is ``gap`` below the sheet's centre, through a penalty contact
(``contact`` stiffness). Rest lengths come from the initial geometry, spring by
spring, so ``degenerate=1`` (the second column of particles moved onto the first:
zero-length springs, zero-area triangles) is a valid, if extreme, cloth: a spring of
length zero exerts no force (its direction is undefined). ``scale`` multiplies every
length (and gravity, so the motion in units of ``scale`` is unchanged): 1e-6 to 1e6
probe the float types' range.

The reference is a float64 small-step RK4 run of the same file
(``kdsl.scenes.reference``); the energy (kinetic, gravity, springs, contact) is
computed on the host in float64, independently of the kernels.

The implicit integrator is ``backward_euler`` with the Jacobi solve of
``kdsl.scenes.integrators``, not XPBD: it converges to the same dynamics as the
other integrators (so its error against the reference is an integrator's error and
the work-precision plots compare like with like), while XPBD's constraint
projection with a fixed iteration count converges to a different, more damped
motion. The Jacobi diagonal is Gershgorin-safe (``cx * sum k / m`` rather than the
exact block diagonal), which keeps the iteration convergent for any stiffness and
step; stiff springs then need more ``jacobi_iters`` for accuracy, never for
stability. The spring Jacobian clamps its geometric term at zero for compressed
springs (the usual definiteness fix) and the contact's keeps its normal part only.
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

#: Neighbour offsets (di, dj): structural then shear springs.
OFFSETS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))
SLOTS = len(OFFSETS)


@cache
def make_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """The cloth kernels for float type ``real``."""
    vec3, Vec3Array, RealArray, IntArray = kernel_types(wp, real)

    @wp.kernel(module="unique")
    def cloth_accel(
        x: Vec3Array,
        v: Vec3Array,
        nbr: IntArray,
        rest: RealArray,
        inv_m: RealArray,
        k: real,
        kd: real,
        gravity: vec3,
        center: vec3,
        radius: real,
        kc: real,
        out: Vec3Array,
    ):
        p = wp.tid()
        xp = x[p]
        vp = v[p]
        f = vec3(real(0.0), real(0.0), real(0.0))
        for s in range(8):
            q = nbr[p * 8 + s]
            if q >= 0:
                d = x[q] - xp
                length = wp.length(d)
                if length > real(0.0):  # a zero-length spring has no direction: no force
                    u = d / length
                    f = f + u * (k * (length - rest[p * 8 + s]) + kd * wp.dot(u, v[q] - vp))
        r = xp - center
        dist = wp.length(r)
        if dist < radius and dist > real(0.0):
            f = f + r * (kc * (radius - dist) / dist)
        a = vec3(real(0.0), real(0.0), real(0.0))
        if inv_m[p] > real(0.0):  # pinned particles do not move
            a = f * inv_m[p] + gravity
        out[p] = a

    @wp.kernel(module="unique")
    def cloth_jvp(
        x: Vec3Array,
        z: Vec3Array,
        nbr: IntArray,
        rest: RealArray,
        inv_m: RealArray,
        k: real,
        kd: real,
        center: vec3,
        radius: real,
        kc: real,
        cx: real,
        cv: real,
        out: Vec3Array,
    ):
        # out_p = (1/m) [cx sum K_s (z_q - z_p) + cv sum kd u u^T (z_q - z_p) - cx kc n n^T z_p]
        # with K_s = k [max(0, 1 - rest/l) (I - u u^T) + u u^T].
        p = wp.tid()
        xp = x[p]
        zp = z[p]
        f = vec3(real(0.0), real(0.0), real(0.0))
        for s in range(8):
            q = nbr[p * 8 + s]
            if q >= 0:
                d = x[q] - xp
                length = wp.length(d)
                if length > real(0.0):
                    u = d / length
                    dz = z[q] - zp
                    along = u * wp.dot(u, dz)
                    geo = wp.max(real(0.0), real(1.0) - rest[p * 8 + s] / length)
                    f = f + (along + (dz - along) * geo) * (cx * k) + along * (cv * kd)
        r = xp - center
        dist = wp.length(r)
        if dist < radius and dist > real(0.0):
            n = r / dist
            f = f - n * (cx * kc * wp.dot(n, zp))
        out[p] = f * inv_m[p]

    @wp.kernel(module="unique")
    def cloth_diag(
        x: Vec3Array,
        nbr: IntArray,
        inv_m: RealArray,
        k: real,
        kd: real,
        center: vec3,
        radius: real,
        kc: real,
        cx: real,
        cv: real,
        out: RealArray,
    ):
        # Gershgorin-safe: each spring block's norm is at most k (kd), so -(cx k + cv kd)
        # per spring bounds the diagonal of cx J_x + cv J_v from below.
        p = wp.tid()
        total = real(0.0)
        for s in range(8):
            q = nbr[p * 8 + s]
            if q >= 0:
                total = total + cx * k + cv * kd
        dist = wp.length(x[p] - center)
        if dist < radius:
            total = total + cx * kc
        out[p] = -total * inv_m[p]

    return SimpleNamespace(cloth_accel=cloth_accel, cloth_jvp=cloth_jvp, cloth_diag=cloth_diag,
                           vec3=vec3)  # fmt: skip


class Cloth(Scene):
    """A mass-spring cloth pinned at two corners falling onto a sphere (see the module doc)."""

    name = "cloth"
    summary = "mass-spring cloth pinned at two corners falling onto a sphere, k 1e2..1e6"
    order = 2
    integrators = ("symplectic_euler", "explicit_euler", "velocity_verlet", "rk4",
                   "backward_euler")  # fmt: skip
    defaults = {"grid": 8, "size": 1.0, "mass": 0.2, "stiffness": 1e3, "damping": 0.0,
                "radius": 0.3, "gap": 0.02, "contact": 1e3, "gravity": -9.81, "scale": 1.0,
                "degenerate": 0, "jacobi_iters": 40}  # fmt: skip
    default_dt = 1e-4
    default_steps = 1000

    def setup(self) -> None:
        p = self.params
        n = self.int_param("grid", 2)
        self.grid_n, L = n, float(p["scale"])
        self.velocity_dependent = p["damping"] != 0.0
        s = np.linspace(-0.5, 0.5, n) * p["size"]
        gi, gj = np.meshgrid(s, s, indexing="ij")
        x0 = np.stack([gi.ravel(), np.zeros(n * n), gj.ravel()], axis=1)
        if p["degenerate"]:
            x0.reshape(n, n, 3)[1] = x0.reshape(n, n, 3)[0]  # column 1 onto column 0
        self.x0 = x0 * L
        self.m = np.full(n * n, p["mass"] / (n * n))
        self.inv_m = 1.0 / self.m
        self.inv_m[[0, n - 1]] = 0.0  # the two corners of the first row are pinned
        nbr = np.full((n * n, SLOTS), -1, dtype=np.int32)
        for i in range(n):
            for j in range(n):
                for s_, (di, dj) in enumerate(OFFSETS):
                    if 0 <= i + di < n and 0 <= j + dj < n:
                        nbr[i * n + j, s_] = (i + di) * n + j + dj
        self.nbr = nbr
        q = np.where(nbr >= 0, nbr, 0)
        self.rest = np.where(nbr >= 0, np.linalg.norm(self.x0[q] - self.x0[:, None], axis=2), 0.0)
        self.g = np.array([0.0, p["gravity"] * L, 0.0])
        self.center = np.array([0.0, -(p["gap"] + p["radius"]) * L, 0.0])
        self.radius = p["radius"] * L

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        k = make_kernels(wp, real)
        dev = self.device
        self.nbr_arr = wp.array(self.nbr.ravel(), dtype=int, device=dev)
        self.rest_arr = wp.array(self.rest.ravel(), dtype=real, device=dev)
        self.inv_m_arr = wp.array(self.inv_m, dtype=real, device=dev)
        self.gravity, self.center_v = k.vec3(*self.g), k.vec3(*self.center)
        return k

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x0.copy(), np.zeros_like(self.x0)

    def _consts(self) -> list[Any]:
        r, p = self.real, self.params
        return [r(p["stiffness"]), r(p["damping"])]

    def _contact(self) -> list[Any]:
        return [self.center_v, self.real(self.radius), self.real(self.params["contact"])]

    def step(self, dt: float) -> None:
        self.last_dt = dt
        super().step(dt)

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        self.launch(self.k.cloth_accel, self.n,
                    [x, v, self.nbr_arr, self.rest_arr, self.inv_m_arr, *self._consts(),
                     self.gravity, *self._contact(), out])  # fmt: skip

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        self.launch(self.k.cloth_jvp, self.n,
                    [x, z, self.nbr_arr, self.rest_arr, self.inv_m_arr, *self._consts(),
                     *self._contact(), self.real(cx), self.real(cv), out])  # fmt: skip

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        self.launch(self.k.cloth_diag, self.n,
                    [x, self.nbr_arr, self.inv_m_arr, *self._consts(), *self._contact(),
                     self.real(cx), self.real(cv), out])  # fmt: skip

    def omega_max(self) -> float:
        """A bound on the fastest frequency: 8 springs (and the contact) on the lightest mass."""
        p = self.params
        return math.sqrt((SLOTS * 2.0 * p["stiffness"] + p["contact"]) / float(np.min(self.m)))

    def picture(self, x: np.ndarray) -> Any:
        """The cloth as a shaded surface over the sphere (``kdsl scene run --render``)."""
        from kdsl.scenes import render

        return render.Picture(x, triangles=render.grid_triangles(self.grid_n),
                              spheres=[(self.center, self.radius)], show_points=False)  # fmt: skip

    def reference(self, t: float) -> np.ndarray:
        return small_step_reference(self, t, getattr(self, "last_dt", self.default_dt))

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float:
        """Kinetic + gravity (from the sphere's centre) + spring + contact energy (float64, host)."""
        assert v is not None
        p = self.params
        free = self.inv_m > 0
        kinetic = 0.5 * np.sum(self.m[free, None] * v[free] ** 2)
        gravity = -np.sum(self.m[:, None] * (x - self.center) * self.g)  # zero at the centre
        q = np.where(self.nbr >= 0, self.nbr, 0)
        length = np.linalg.norm(x[q] - x[:, None], axis=2)
        springs = (
            0.25 * p["stiffness"] * np.sum(np.where(self.nbr >= 0, (length - self.rest) ** 2, 0))
        )
        dist = np.linalg.norm(x - self.center, axis=1)
        contact = 0.5 * p["contact"] * np.sum(np.maximum(self.radius - dist, 0.0) ** 2)
        return float(kinetic + gravity + springs + contact)

    def stability_measure(self, x: np.ndarray, v: np.ndarray | None) -> float:
        """Kinetic energy plus one: the falling sheet's energy changes sign as it falls."""
        assert v is not None
        return float(
            1.0 + 0.5 * np.sum(self.m[:, None] * v**2) / max(self.params["scale"], 1e-300) ** 2
        )

    def theory_dt_limit(self, integrator: str) -> float | None:
        return math.inf if integrator == "backward_euler" else None
