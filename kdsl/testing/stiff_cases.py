"""Differentiable programs where naive gradients fail: stiff springs, long horizons, data-dependent loops.

Each program is written once against a Warp-compatible module (``build(kdsl)`` or
``build(warp)``), so the same source runs under kdsl and under Warp, and has a
NumPy float64 twin that gives the finite-difference reference. ``evaluate``
differentiates one program under one framework and classifies the result:

- ``ok``: matches central differences of the float64 reference;
- ``ill-conditioned``: the reference itself is unstable (two step sizes disagree),
  so no finite-difference check is meaningful; the gradient must still be finite;
- ``wrong``: a finite gradient that disagrees with a well-conditioned reference;
- ``nan``: a NaN or infinite gradient.

``tests/autodiff/test_stiff_cases.py`` requires every kdsl result to be ``ok`` or
``ill-conditioned``; ``benchmarks/autodiff_accuracy.py`` prints kdsl and Warp side by side.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np


def build(wp: Any) -> dict[str, Any]:
    """The kernels, compiled by ``wp`` (kdsl or warp). All state is float64."""
    f64 = wp.float64

    @wp.kernel
    def spring_explicit(k: wp.array(dtype=f64), x0: wp.array(dtype=f64), steps: int,
                        dt: f64, out: wp.array(dtype=f64)):  # fmt: skip
        i = wp.tid()
        x = x0[i]
        v = f64(0.0)
        stiff = k[0]
        for _s in range(steps):
            a = -stiff * x
            x = x + v * dt
            v = v + a * dt
        out[i] = x

    @wp.kernel
    def spring_semi_implicit(k: wp.array(dtype=f64), x0: wp.array(dtype=f64), steps: int,
                             dt: f64, out: wp.array(dtype=f64)):  # fmt: skip
        i = wp.tid()
        x = x0[i]
        v = f64(0.0)
        stiff = k[0]
        for _s in range(steps):
            v = v - stiff * x * dt
            x = x + v * dt
        out[i] = x

    @wp.kernel
    def damped_long(k: wp.array(dtype=f64), x0: wp.array(dtype=f64), steps: int, dt: f64,
                    out: wp.array(dtype=f64)):  # fmt: skip
        # Heavy damping over a long horizon: the gradient with respect to x0 vanishes.
        i = wp.tid()
        x = x0[i]
        v = f64(0.0)
        stiff = k[0]
        for _s in range(steps):
            v = v + (-stiff * x - f64(20.0) * v) * dt
            x = x + v * dt
        out[i] = x

    @wp.kernel
    def fall_until_ground(k: wp.array(dtype=f64), x0: wp.array(dtype=f64), steps: int,
                          dt: f64, out: wp.array(dtype=f64)):  # fmt: skip
        # The trip count depends on the data: fall (with drag k) until below the ground.
        i = wp.tid()
        x = x0[i]
        v = f64(0.0)
        drag = k[0]
        n = int(0)  # noqa: UP018, RUF046 - Warp needs a typed variable to mutate in a loop
        while x > f64(0.0) and n < steps:
            v = v + (f64(-9.81) - drag * v) * dt
            x = x + v * dt
            n = n + 1
        out[i] = v + x

    return {
        "spring_explicit": spring_explicit,
        "spring_semi_implicit": spring_semi_implicit,
        "damped_long": damped_long,
        "fall_until_ground": fall_until_ground,
    }


def _spring_explicit(k, x0, steps, dt):
    x, v = x0.copy(), np.zeros_like(x0)
    for _ in range(steps):
        x, v = x + v * dt, v - k * x * dt
    return x


def _spring_semi(k, x0, steps, dt):
    x, v = x0.copy(), np.zeros_like(x0)
    for _ in range(steps):
        v = v - k * x * dt
        x = x + v * dt
    return x


def _damped(k, x0, steps, dt):
    x, v = x0.copy(), np.zeros_like(x0)
    for _ in range(steps):
        v = v + (-k * x - 20.0 * v) * dt
        x = x + v * dt
    return x


def _fall(k, x0, steps, dt):
    out = np.empty_like(x0)
    for i, xi in enumerate(x0):
        x, v, n = xi, 0.0, 0
        while x > 0.0 and n < steps:
            v = v + (-9.81 - k * v) * dt
            x = x + v * dt
            n += 1
        out[i] = v + x
    return out


@dataclass(frozen=True)
class StiffCase:
    """One program with its parameters and float64 reference."""

    name: str
    kernel: str
    stiffness: float
    x0: tuple[float, ...]
    steps: int
    dt: float
    reference: Callable[..., np.ndarray]
    what: str


CASES = [
    StiffCase("stiff spring, explicit Euler", "spring_explicit", 1.0e4, (0.1, -0.2, 0.3), 1000,
              1.0e-3, _spring_explicit, "1000 steps at dt*omega = 0.1: the state and gradients "
              "grow about 150x"),
    StiffCase("stiff spring, semi-implicit Euler", "spring_semi_implicit", 1.0e4,
              (0.1, -0.2, 0.3), 1000, 1.0e-3, _spring_semi,
              "1000 steps of a stable symplectic integrator"),
    StiffCase("damped, long horizon", "damped_long", 50.0, (1.0, 2.0, -1.0), 5000, 1.0e-3,
              _damped, "5000 steps of heavy damping: gradients shrink about a million-fold"),
    StiffCase("fall until ground (data-dependent loop)", "fall_until_ground", 0.5,
              (1.0, 2.5, 4.0), 100000, 1.0e-3, _fall,
              "a while loop whose trip count (450 to 910) depends on x0 and k"),
]  # fmt: skip


def reference_gradients(case: StiffCase) -> tuple[np.ndarray, np.ndarray, bool]:
    """d sum(out) / d k and d sum(out) / d x0 by central differences in float64.

    The third value is False when two step sizes disagree (ill-conditioned).
    """
    x0 = np.array(case.x0)

    def loss(k, x):
        return float(np.sum(case.reference(k, x, case.steps, case.dt)))

    estimates = []
    for rel in (1e-6, 1e-5):
        hk = rel * abs(case.stiffness)
        gk = (loss(case.stiffness + hk, x0) - loss(case.stiffness - hk, x0)) / (2 * hk)
        gx = np.empty_like(x0)
        for j in range(len(x0)):
            h = rel * max(abs(x0[j]), 1.0)
            e = np.zeros_like(x0)
            e[j] = h
            gx[j] = (loss(case.stiffness, x0 + e) - loss(case.stiffness, x0 - e)) / (2 * h)
        estimates.append((np.array([gk]), gx))
    (gk1, gx1), (gk2, gx2) = estimates
    stable = np.allclose(gk1, gk2, rtol=1e-4, atol=1e-30) and np.allclose(
        gx1, gx2, rtol=1e-4, atol=1e-30
    )
    return gk1, gx1, stable


def framework_gradients(wp: Any, kernels: dict[str, Any], case: StiffCase,
                        device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """d sum(out) / d k and d x0 from ``wp``'s adjoint launch (kdsl or warp)."""
    kernel = kernels[case.kernel]
    n = len(case.x0)
    k = wp.array(np.array([case.stiffness]), dtype=wp.float64, device=device, requires_grad=True)
    x0 = wp.array(np.array(case.x0), dtype=wp.float64, device=device, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, device=device, requires_grad=True)
    inputs = [k, x0, case.steps, case.dt]
    wp.launch(kernel, dim=n, inputs=inputs, outputs=[out], device=device)
    out.grad = wp.array(np.ones(n), dtype=wp.float64, device=device)
    wp.launch(kernel, dim=n, inputs=inputs, outputs=[out], adj_inputs=[k.grad, x0.grad, 0, 0.0],
              adj_outputs=[out.grad], adjoint=True, device=device)  # fmt: skip
    return k.grad.numpy().copy(), x0.grad.numpy().copy()


def classify(got: tuple[np.ndarray, np.ndarray], want: tuple[np.ndarray, np.ndarray],
             stable: bool, rtol: float = 1e-5) -> str:  # fmt: skip
    """``ok``, ``ill-conditioned``, ``wrong`` or ``nan`` (see the module docstring)."""
    values = np.concatenate([np.ravel(g) for g in got])
    if not np.all(np.isfinite(values)):
        return "nan"
    if not stable:
        return "ill-conditioned"
    ref = np.concatenate([np.ravel(w) for w in want])
    scale = np.max(np.abs(ref)) if ref.size else 1.0
    ok = np.all(np.abs(values - ref) <= rtol * np.abs(ref) + 1e-9 * scale + 1e-300)
    return "ok" if ok else "wrong"


def evaluate(wp: Any, kernels: dict[str, Any], case: StiffCase, device: str = "cpu") -> dict:
    """One row of the comparison: gradients, reference and the verdict."""
    gk, gx, stable = reference_gradients(case)
    got = framework_gradients(wp, kernels, case, device)
    return {
        "case": case.name,
        "verdict": classify(got, (gk, gx), stable),
        "d_k": float(got[0][0]),
        "d_k_reference": float(gk[0]),
        "d_x0": [float(v) for v in got[1]],
        "d_x0_reference": [float(v) for v in gx],
    }
