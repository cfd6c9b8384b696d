"""ocean: the seeds' ocean surface, a sum of Gerstner waves on a grid.

Each grid point with rest position ``a`` (a ``size`` x ``size`` patch, ``grid`` x
``grid`` points) moves as

    x = a - sum_w Q_w A_w D_w sin(theta_w),   y = sum_w A_w cos(theta_w),
    theta_w = k_w D_w . a - omega_w t + phi_w,   omega_w^2 = g k_w (deep water)

for ``waves`` waves (seeded wavelengths 2 to 40 m around a wind direction,
amplitudes ``A = steepness / k`` over the wave count, so the surface never folds).
One kernel evaluates the surface at a time; the scene has no dynamics to integrate,
so its one "integrator" is ``analytic``, and its error is the precision's alone:
``max |x - x_ref| / sum A`` against the float64 surface. At large times (``t0``)
the phase ``omega t`` cancels against ``k D . a`` and float32 loses the surface
(float16 cannot even hold ``t0 = 1e5``); ``host_phase=1`` reduces
``phi_w - omega_w t`` modulo 2 pi in float64 on the host each frame, which fixes it.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables.

import math
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.base import Scene
from kdsl.scenes.binding import kernel_types

GRAVITY = 9.81


@cache
def make_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """The ocean kernel for float type ``real``."""
    vec3, Vec3Array, RealArray, _ = kernel_types(wp, real)

    @wp.kernel(module="unique")
    def gerstner(
        rest: Vec3Array,
        dir_x: RealArray,
        dir_z: RealArray,
        wavenumber: RealArray,
        omega: RealArray,
        amplitude: RealArray,
        steep: RealArray,
        phase: RealArray,
        t: real,
        out: Vec3Array,
    ):
        i = wp.tid()
        a = rest[i]
        p = a
        for w in range(omega.shape[0]):
            theta = wavenumber[w] * (dir_x[w] * a[0] + dir_z[w] * a[2]) - omega[w] * t + phase[w]
            s = wp.sin(theta)
            qa = steep[w] * amplitude[w]
            p = p + vec3(-qa * dir_x[w] * s, amplitude[w] * wp.cos(theta), -qa * dir_z[w] * s)
        out[i] = p

    return SimpleNamespace(gerstner=gerstner, vec3=vec3)


class Ocean(Scene):
    """A sum of Gerstner waves evaluated on a grid (see the module docstring)."""

    name = "ocean"
    summary = "the seeds' ocean: a sum of Gerstner waves on a grid (precision error only)"
    order = 1
    integrators = ("analytic",)
    defaults = {"grid": 64, "size": 100.0, "waves": 8, "steepness": 0.5, "t0": 0.0,
                "host_phase": 0, "seed": 3}  # fmt: skip
    default_dt = 1.0 / 60.0
    default_steps = 120
    error_what = "max |x - x_ref| / sum of amplitudes"

    def setup(self) -> None:
        p = self.params
        n, nw = int(p["grid"]), int(p["waves"])
        if n < 1 or nw < 1:
            from kdsl.scenes.binding import SceneError

            raise SceneError(f"ocean needs grid >= 1 and waves >= 1, not {n} and {nw}")
        rng = np.random.default_rng(int(p["seed"]))
        angle = 0.4 + rng.uniform(-0.6, 0.6, nw)  # around the wind
        self.dx, self.dz = np.cos(angle), np.sin(angle)
        self.kw = 2.0 * np.pi / rng.uniform(2.0, 40.0, nw)
        self.om = np.sqrt(GRAVITY * self.kw)
        self.amp = p["steepness"] / (self.kw * nw)
        self.q = np.ones(nw)
        self.phi = rng.uniform(0.0, 2.0 * np.pi, nw)
        s = np.linspace(-0.5, 0.5, n) * p["size"]
        gx, gz = np.meshgrid(s, s, indexing="ij")
        self.rest = np.stack([gx.ravel(), np.zeros(n * n), gz.ravel()], axis=1)

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        dev = self.device
        self.waves = [wp.array(a, dtype=real, device=dev)
                      for a in (self.dx, self.dz, self.kw, self.om, self.amp, self.q)]  # fmt: skip
        self.phase_arr = wp.array(self.phi, dtype=real, device=dev)
        self.rest_arr = wp.array(self.rest, dtype=wp.types.vector(3, real), device=dev)
        return make_kernels(wp, real)

    def initial_state(self) -> tuple[np.ndarray, None]:
        return self.surface(0.0), None

    def surface(self, t: float) -> np.ndarray:
        """The float64 surface at scene time ``t`` (absolute time ``t0 + t``)."""
        tau = self.params["t0"] + t
        theta = np.outer(self.rest[:, 0], self.kw * self.dx) + np.outer(
            self.rest[:, 2], self.kw * self.dz
        )
        theta += self.phi - self.om * tau
        s, c = np.sin(theta), np.cos(theta)
        x = self.rest.copy()
        x[:, 0] -= s @ (self.q * self.amp * self.dx)
        x[:, 1] += c @ self.amp
        x[:, 2] -= s @ (self.q * self.amp * self.dz)
        return x

    def evaluate(self, t: float) -> None:
        """Launch the surface at scene time ``t`` into ``self.x``."""
        tau = self.params["t0"] + t
        if self.params["host_phase"]:
            # phi - omega tau, reduced mod 2 pi in float64: no large phase reaches the kernel.
            reduced = np.mod(self.phi - self.om * tau, 2.0 * np.pi)
            self.phase_arr.assign(self.wp.array(reduced, dtype=self.real, device=self.device))
            tau = 0.0
        self.launch(self.k.gerstner, self.n,
                    [self.rest_arr, *self.waves, self.phase_arr, self.real(tau), self.x])  # fmt: skip

    def picture(self, x: np.ndarray) -> Any:
        """The surface, colored by height (``kdsl scene run --render``)."""
        from kdsl.scenes import render

        n = int(self.params["grid"])
        return render.Picture(x, triangles=render.grid_triangles(n), values=x[:, 1],
                              show_points=False)  # fmt: skip

    def reference(self, t: float) -> np.ndarray:
        return self.surface(t)

    def error(self) -> float:
        x, _ = self.state()
        err = float(np.max(np.abs(x - self.reference(self.t)))) / float(np.sum(self.amp))
        return err if math.isfinite(err) else math.inf
