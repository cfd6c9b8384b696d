"""throw: optimize launch velocities through ``wp.Tape`` so ballistic particles hit targets.

``count`` particles are thrown from the origin with linear drag ``c`` (unit mass,
``a = g - c v``) for a flight of ``flight`` seconds; each must land on its own
target. One step of this scene is one gradient-descent iteration: the flight of
``round(flight / dt)`` steps is recorded on a ``Tape`` (every step writes new
arrays, so the tape can replay it backwards), the loss ``sum |x(T) - target|^2`` is
accumulated by ``atomic_add``, ``tape.backward`` gives ``dL/dv0``, and ``v0`` moves
down the gradient (``learning_rate`` in units of the exact Gauss-Newton step).

The error is the gradient's: ``max |g - g_fd| / max |g_fd|`` at the initial launch
velocities, with ``g_fd`` the float64 central finite differences of the exact
(closed-form) loss. So it shrinks with dt at the flight integrator's order until the
precision's floor; ``discrete_fd_gradient`` gives the finite differences of the
discrete flight instead, which the tape must match to round-off (a test checks).
The integrators are fused one-launch steps of the same five methods.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables.

import math
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.base import Scene
from kdsl.scenes.binding import kernel_types

#: Integrator name -> the ``method`` switch of ``throw_step``.
METHODS = {"symplectic_euler": 0, "explicit_euler": 1, "velocity_verlet": 2, "rk4": 3,
           "backward_euler": 4}  # fmt: skip
#: The finite differences' relative step (central differences: error ~ step^2).
FD_STEP = 1e-5


@cache
def make_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """The throw kernels for float type ``real``."""
    vec3, Vec3Array, RealArray, _ = kernel_types(wp, real)

    @wp.kernel(module="unique")
    def throw_step(
        x: Vec3Array,
        v: Vec3Array,
        g: vec3,
        c: real,
        h: real,
        method: int,
        x1: Vec3Array,
        v1: Vec3Array,
    ):
        # One flight step with a = g - c v, writing new arrays (the tape replays it).
        i = wp.tid()
        x0 = x[i]
        v0 = v[i]
        half = real(0.5) * h
        xn = x0
        vn = v0
        if method == 0:  # symplectic Euler
            vn = v0 + (g - c * v0) * h
            xn = x0 + vn * h
        elif method == 1:  # explicit Euler
            xn = x0 + v0 * h
            vn = v0 + (g - c * v0) * h
        elif method == 2:  # velocity Verlet, end acceleration at a predicted velocity
            vh = v0 + (g - c * v0) * half
            xn = x0 + vh * h
            vp = vh + (g - c * vh) * half
            vn = vh + (g - c * vp) * half
        elif method == 3:  # RK4 on (x, v)
            k1 = g - c * v0
            v2 = v0 + k1 * half
            k2 = g - c * v2
            v3 = v0 + k2 * half
            k3 = g - c * v3
            v4 = v0 + k3 * h
            k4 = g - c * v4
            xn = x0 + (v0 + real(2.0) * (v2 + v3) + v4) * (h / real(6.0))
            vn = v0 + (k1 + real(2.0) * (k2 + k3) + k4) * (h / real(6.0))
        else:  # backward Euler: (1 + h c) v1 = v0 + h g, exactly
            vn = (v0 + g * h) / (real(1.0) + h * c)
            xn = x0 + vn * h
        x1[i] = xn
        v1[i] = vn

    @wp.kernel(module="unique")
    def miss_loss(x: Vec3Array, target: Vec3Array, loss: RealArray):
        i = wp.tid()
        d = x[i] - target[i]
        wp.atomic_add(loss, 0, wp.dot(d, d))

    @wp.kernel(module="unique")
    def descend(v: Vec3Array, grad: Vec3Array, rate: real):
        i = wp.tid()
        v[i] = v[i] - grad[i] * rate

    return SimpleNamespace(throw_step=throw_step, miss_loss=miss_loss, descend=descend,
                           vec3=vec3)  # fmt: skip


def exact_landing(v0: np.ndarray, g: np.ndarray, c: float, t: float) -> np.ndarray:
    """``x(t)`` from the origin with launch velocity ``v0`` (float64, closed form)."""
    v_inf = g / c
    return v_inf * t + (v0 - v_inf) * (-math.expm1(-c * t)) / c


def host_flight(v0: np.ndarray, g: np.ndarray, c: float, h: float, steps: int,
                method: str) -> np.ndarray:  # fmt: skip
    """The discrete flight's landing point in float64 (the kernels' formulas on the host)."""
    x, v = np.zeros_like(v0), v0.copy()

    def a(u: np.ndarray) -> np.ndarray:
        return g - c * u

    for _ in range(steps):
        if method == "symplectic_euler":
            v = v + h * a(v)
            x = x + h * v
        elif method == "explicit_euler":
            x, v = x + h * v, v + h * a(v)
        elif method == "velocity_verlet":
            vh = v + 0.5 * h * a(v)
            x = x + h * vh
            v = vh + 0.5 * h * a(vh + 0.5 * h * a(vh))
        elif method == "rk4":
            v2 = v + 0.5 * h * a(v)
            v3 = v + 0.5 * h * a(v2)
            v4 = v + h * a(v3)
            x = x + h / 6 * (v + 2 * (v2 + v3) + v4)
            v = v + h / 6 * (a(v) + 2 * (a(v2) + a(v3)) + a(v4))
        else:
            v = (v + h * g) / (1.0 + h * c)
            x = x + h * v
    return x


def central_differences(loss: Any, v0: np.ndarray) -> np.ndarray:
    """``d loss / d v0`` by float64 central differences (``loss`` sums per-throw terms)."""
    grad = np.zeros_like(v0)
    for comp in range(3):
        step = FD_STEP * (1.0 + np.abs(v0[:, comp]))
        up, down = v0.copy(), v0.copy()
        up[:, comp] += step
        down[:, comp] -= step
        grad[:, comp] = (loss(up) - loss(down)) / (2.0 * step)
    return grad


class Throw(Scene):
    """Launch velocities optimized through the tape (see the module docstring)."""

    name = "throw"
    summary = "differentiable: launch velocities through wp.Tape; error = gradient vs float64 FD"
    order = 2
    integrators = tuple(METHODS)
    defaults = {"count": 64, "drag": 0.5, "gravity": -9.81, "flight": 1.0, "learning_rate": 0.5}
    default_dt = 1e-2
    default_steps = 10
    error_what = "max |dL/dv0 - FD| / max |FD| (float64 finite differences of the exact loss)"

    def setup(self) -> None:
        p = self.params
        n = int(p["count"])
        if n < 1 or p["flight"] <= 0 or p["drag"] <= 0:
            from kdsl.scenes.binding import SceneError

            raise SceneError("throw needs count >= 1, flight > 0 and drag > 0")
        i = np.arange(n)
        angle = 2.0 * np.pi * i / n
        dist = 3.0 + 2.0 * (i % 4)
        self.targets = np.stack([dist * np.cos(angle), np.zeros(n), dist * np.sin(angle)], axis=1)
        self.g = np.array([0.0, p["gravity"], 0.0])
        self.c = float(p["drag"])
        self.guess = np.stack([np.cos(angle), np.full(n, 4.0), np.sin(angle)], axis=1)
        # x(T) = A + s v0 with s = (1 - e^{-cT}) / c: the Gauss-Newton step is 1 / (2 s^2).
        s = -math.expm1(-self.c * p["flight"]) / self.c
        self.rate = p["learning_rate"] / (2.0 * s * s)

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        k = make_kernels(wp, real)
        self.target_arr = wp.array(self.targets, dtype=k.vec3, device=self.device)
        self.gravity = k.vec3(*self.g)
        self._flights: dict[int, tuple[list, list, Any]] = {}
        return k

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """x: the last flight's landing points; v: the launch velocities being optimized."""
        return np.zeros_like(self.guess), self.guess.copy()

    def flight_steps(self, dt: float) -> int:
        """Steps of one flight at ``dt`` (the flight time is rounded to whole steps)."""
        return max(1, round(self.params["flight"] / dt))

    def _arrays(self, steps: int) -> tuple[list, list, Any]:
        arrays = self._flights.get(steps)
        if arrays is None:
            wp, dev, vec3 = self.wp, self.device, self.k.vec3
            xs = [
                wp.zeros(self.n, dtype=vec3, device=dev, requires_grad=True)
                for _ in range(steps + 1)
            ]
            vs = [
                wp.zeros(self.n, dtype=vec3, device=dev, requires_grad=True)
                for _ in range(steps + 1)
            ]
            loss = wp.zeros(1, dtype=self.real, device=dev, requires_grad=True)
            arrays = self._flights[steps] = (xs, vs, loss)
        return arrays

    def gradient(self, v0: Any, dt: float, land: bool = True) -> tuple[Any, Any]:
        """``dL/dv0`` (an array) and the loss, from one taped flight and its backward pass.

        ``land``: copy the landing points into ``self.x`` (the scene's state).
        """
        steps = self.flight_steps(dt)
        h = self.params["flight"] / steps
        xs, vs, loss = self._arrays(steps)
        xs[0].zero_()
        vs[0].assign(v0)
        loss.zero_()
        tape = self.wp.Tape()
        with tape:
            for k in range(steps):
                self.launch(self.k.throw_step, self.n,
                            [xs[k], vs[k], self.gravity, self.real(self.c), self.real(h),
                             METHODS[self.integrator], xs[k + 1], vs[k + 1]])  # fmt: skip
            self.launch(self.k.miss_loss, self.n, [xs[steps], self.target_arr, loss])
        tape.backward(loss=loss)
        grad = self.wp.clone(vs[0].grad)
        tape.zero()
        if land:
            self.x.assign(xs[steps])
        return grad, loss

    def step(self, dt: float) -> None:
        """One gradient-descent iteration on the launch velocities."""
        grad, _ = self.gradient(self.v, dt)
        self.launch(self.k.descend, self.n, [self.v, grad, self.real(self.rate)])
        self.last_dt = dt
        self.t += dt

    def exact_loss_terms(self, v0: np.ndarray) -> np.ndarray:
        """Per throw, ``|x(T) - target|^2`` of the exact flight (float64)."""
        d = exact_landing(v0, self.g, self.c, self.params["flight"]) - self.targets
        return np.sum(d * d, axis=1)

    def discrete_fd_gradient(self, dt: float) -> np.ndarray:
        """Central differences of the discrete flight's loss at the initial guess (float64)."""
        steps = self.flight_steps(dt)
        h = self.params["flight"] / steps

        def loss(v0: np.ndarray) -> np.ndarray:
            d = host_flight(v0, self.g, self.c, h, steps, self.integrator) - self.targets
            return np.sum(d * d, axis=1)

        return central_differences(loss, self.guess)

    def reference(self, t: float) -> np.ndarray:
        """The exact loss's gradient at the initial guess (float64 central differences)."""
        return central_differences(self.exact_loss_terms, self.guess)

    def error(self) -> float:
        dt = getattr(self, "last_dt", self.default_dt)
        v0 = self.wp.array(self.guess, dtype=self.k.vec3, device=self.device)
        grad, _ = self.gradient(v0, dt, land=False)
        g = grad.numpy().astype(np.float64)
        ref = self.reference(self.t)
        err = float(np.max(np.abs(g - ref)) / np.max(np.abs(ref)))
        return err if math.isfinite(err) else math.inf

    def extra_errors(self) -> dict[str, float]:
        """How far the optimized throws land from their targets (exact flight, metres)."""
        v = self.v.numpy().astype(np.float64)
        miss = exact_landing(v, self.g, self.c, self.params["flight"]) - self.targets
        return {"max miss (m)": float(np.max(np.linalg.norm(miss, axis=1)))}

    def stability_measure(self, x: np.ndarray, v: np.ndarray | None) -> float:
        """The launch speeds: they stay bounded while the descent converges."""
        assert v is not None
        return float(np.max(np.abs(v)))
