"""Whole programs: the seed kernels (integrate, saxpy, matmul, rosenbrock) and n-body.

``make_programs()`` defines the kernels afresh on every call, so a benchmark can
measure the frontend from a cold start; the cases use one set of them.
"""

from typing import Any

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, uniform


def make_programs() -> dict[str, Any]:
    """Fresh kernel objects: integrate, saxpy, matmul, rosenbrock and nbody."""

    @wp.kernel
    def integrate(
        x: wp.array(dtype=wp.vec3),
        v: wp.array(dtype=wp.vec3),
        f: wp.array(dtype=wp.vec3),
        w: wp.array(dtype=float),
        gravity: wp.vec3,
        dt: float,
    ):
        # thread id
        tid = wp.tid()
        x0 = x[tid]
        v0 = v[tid]
        # Semi-implicit Euler step
        f_ext = f[tid]
        inv_mass = w[tid]
        v1 = v0 + (f_ext * inv_mass + gravity) * dt
        x1 = x0 + v1 * dt
        # store results
        x[tid] = x1
        v[tid] = v1

    @wp.kernel
    def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
        i = wp.tid()
        y[i] = a * x[i] + y[i]

    @wp.kernel
    def matmul(a: wp.array2d(dtype=float), b: wp.array2d(dtype=float), c: wp.array2d(dtype=float)):
        # launch dims should be (N, M)
        i, j = wp.tid()
        N = a.shape[0]
        K = a.shape[1]
        M = b.shape[1]
        if i < N and j < M:
            s = wp.float32(0)
            for k in range(K):
                s += a[i, k] * b[k, j]
            c[i, j] = s

    @wp.func
    def rosenbrock_fn(x: float, y: float):
        return (1.0 - x) ** 2.0 + 100.0 * (y - x**2.0) ** 2.0

    @wp.kernel
    def rosenbrock(xs: wp.array(dtype=wp.vec2), z: wp.array(dtype=float)):
        i = wp.tid()
        x = xs[i]
        z[i] = rosenbrock_fn(x[0], x[1])

    @wp.kernel
    def nbody(
        pos: wp.array(dtype=wp.vec3),
        mass: wp.array(dtype=float),
        acc: wp.array(dtype=wp.vec3),
        eps2: float,
    ):
        # All-pairs gravitational acceleration with Plummer softening.
        i = wp.tid()
        p = pos[i]
        a = wp.vec3(0.0, 0.0, 0.0)
        for j in range(pos.shape[0]):
            d = pos[j] - p
            r2 = wp.dot(d, d) + eps2
            inv_r = 1.0 / wp.sqrt(r2)
            a = a + d * (mass[j] * inv_r * inv_r * inv_r)
        acc[i] = a

    return {"integrate": integrate, "saxpy": saxpy, "matmul": matmul,
            "rosenbrock": rosenbrock, "nbody": nbody}  # fmt: skip


def nbody_reference(pos: np.ndarray, mass: np.ndarray, eps2: float) -> np.ndarray:
    """All-pairs accelerations in float64 (the oracle for the nbody kernel)."""
    p = f64(pos)
    d = p[None, :, :] - p[:, None, :]
    inv_r = 1.0 / np.sqrt(np.sum(d * d, axis=2) + eps2)
    return np.einsum("ijk,ij->ik", d, f64(mass)[None, :] * inv_r**3)


PROGRAMS = make_programs()


def _integrate_inputs(rng):
    n = 64
    return {"x": uniform(rng, (n, 3), -1, 1), "v": uniform(rng, (n, 3), -1, 1),
            "f": uniform(rng, (n, 3), -1, 1), "w": uniform(rng, n, 0.5, 2.0),
            "gravity": np.array([0.0, -9.8, 0.0], np.float32), "dt": 0.01}  # fmt: skip


def _integrate_ref(ins):
    v1 = f64(ins["v"]) + (f64(ins["f"]) * f64(ins["w"])[:, None] + f64(ins["gravity"])) * ins["dt"]
    return {"x": f64(ins["x"]) + v1 * ins["dt"], "v": v1}


def _matmul_inputs(rng):
    return {
        "a": uniform(rng, (6, 4), -1, 1),
        "b": uniform(rng, (4, 5), -1, 1),
        "c": np.zeros((6, 5), np.float32),
    }


def _nbody_inputs(rng):
    n = 32
    return {
        "pos": uniform(rng, (n, 3), -1, 1),
        "mass": uniform(rng, n, 0.1, 1.0),
        "acc": np.zeros((n, 3), np.float32),
        "eps2": 0.01,
    }


CASES = [
    Case("program_integrate", PROGRAMS["integrate"], 64, _integrate_inputs, _integrate_ref,
         ("x", "v")),
    Case("program_saxpy", PROGRAMS["saxpy"], 100,
         lambda rng: {"x": uniform(rng, 100, -10, 10), "y": uniform(rng, 100, -10, 10), "a": 1.5},
         lambda ins: {"y": 1.5 * f64(ins["x"]) + f64(ins["y"])}, ("y",)),
    Case("program_matmul", PROGRAMS["matmul"], (7, 6), _matmul_inputs,
         lambda ins: {"c": f64(ins["a"]) @ f64(ins["b"])}, ("c",)),
    Case("program_rosenbrock", PROGRAMS["rosenbrock"], 50,
         lambda rng: {"xs": uniform(rng, (50, 2), -2, 2), "z": np.zeros(50, np.float32)},
         lambda ins: {"z": (1 - f64(ins["xs"])[:, 0]) ** 2
                      + 100 * (f64(ins["xs"])[:, 1] - f64(ins["xs"])[:, 0] ** 2) ** 2},
         ("z",), tol=(1e-5, 1e-4)),
    Case("program_nbody", PROGRAMS["nbody"], 32, _nbody_inputs,
         lambda ins: {"acc": nbody_reference(ins["pos"], ins["mass"], ins["eps2"])}, ("acc",),
         tol=(1e-4, 1e-4)),
]  # fmt: skip
