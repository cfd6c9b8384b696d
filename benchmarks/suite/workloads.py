"""Workload definitions shared by every framework and device: sizes, inputs, references.

Workloads are device-neutral: the same sizes, inputs and references serve the CPU
benchmark and the GPU one, and each ``*_impl`` runner takes the device ("cpu" or
"cuda:0"). ``CUDA_WORKLOADS`` adds the rows only the GPU benchmark runs.

A ``Workload`` says how big it is (full and ``--quick`` size), makes its float32
inputs (the same arrays for every framework), computes the float64 NumPy reference
of one step and judges a framework's result against it. Frameworks implement the
step themselves (``*_impl.py``); this module holds no framework code.

Errors are relative to the reference's largest magnitude: ``max|got - want| /
max|want|`` over each output, so a tolerance reads as "this many ulps of the
largest value" and does not blow up where a value happens to be near zero.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

Inputs = dict[str, np.ndarray | float | int]
Outputs = dict[str, np.ndarray]

#: The n-body rows checked against the float64 reference (an all-pairs reference
#: for every row of 16384 bodies would need gigabytes).
NBODY_CHECK_ROWS = 256


@dataclass(frozen=True)
class Workload:
    """One benchmark problem: see the module docstring.

    ``size`` and ``quick_size`` are the problem size (elements, bodies or grid side);
    ``reference(inputs)`` gives the float64 outputs of one step (or, for n-body,
    those of the checked rows); ``tolerance`` bounds the relative error.
    """

    name: str
    title: str
    size: int
    quick_size: int
    make_inputs: Callable[[int, np.random.Generator], Inputs]
    reference: Callable[[Inputs], Outputs]
    tolerance: float
    outputs: tuple[str, ...]
    reps: int = 10
    #: "step" (a timed step), "launch" (per-launch overhead, microseconds).
    kind: str = "step"
    fast_math: bool = False
    notes: str = ""
    select: Callable[[Inputs, Outputs], Outputs] | None = field(default=None, repr=False)
    #: The ``RUNNERS`` key of the impl modules when it differs from ``name`` (a size variant).
    impl: str = ""

    @property
    def runner_name(self) -> str:
        """The key of this workload's runner in an impl module's ``RUNNERS``."""
        return self.impl or self.name

    def inputs(self, quick: bool, seed: int = 1234) -> Inputs:
        """Fresh float32 inputs at the full or quick size (same seed, same data)."""
        return self.make_inputs(
            self.quick_size if quick else self.size, np.random.default_rng(seed)
        )

    def error(self, inputs: Inputs, got: Outputs, want: Outputs | None = None) -> float:
        """The largest relative error of ``got`` (one step from ``inputs``); ``want`` is
        ``reference(inputs)`` when the caller already has it."""
        if want is None:
            want = self.reference(inputs)
        if self.select is not None:
            got = self.select(inputs, got)
        worst = 0.0
        for name in self.outputs:
            g = np.asarray(got[name], dtype=np.float64).reshape(want[name].shape)
            scale = float(np.max(np.abs(want[name]))) or 1.0
            err = float(np.max(np.abs(g - want[name]))) / scale
            if not np.isfinite(err):
                return float("inf")
            worst = max(worst, err)
        return worst


def f64(a) -> np.ndarray:
    """``a`` as a float64 array."""
    return np.asarray(a, dtype=np.float64)


def _f32(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


# -- saxpy --------------------------------------------------------------------
def saxpy_inputs(n: int, rng: np.random.Generator) -> Inputs:
    """x, y uniform in [-1, 1), a = 2."""
    return {"x": _f32(rng.uniform(-1, 1, n)), "y": _f32(rng.uniform(-1, 1, n)), "a": 2.0}


def saxpy_reference(ins: Inputs) -> Outputs:
    return {"y": ins["a"] * f64(ins["x"]) + f64(ins["y"])}


# -- particles (the seeds' integrate) -------------------------------------------
def particles_inputs(n: int, rng: np.random.Generator) -> Inputs:
    """Positions, velocities, forces (n, 3), inverse masses, gravity, dt."""
    return {
        "x": _f32(rng.uniform(-1, 1, (n, 3))),
        "v": _f32(rng.uniform(-1, 1, (n, 3))),
        "f": _f32(rng.uniform(-1, 1, (n, 3))),
        "w": _f32(rng.uniform(0.5, 2.0, n)),
        "gravity": _f32([0.0, -9.8, 0.0]),
        "dt": 0.01,
    }


def particles_reference(ins: Inputs) -> Outputs:
    dt = ins["dt"]
    v1 = f64(ins["v"]) + (f64(ins["f"]) * f64(ins["w"])[:, None] + f64(ins["gravity"])) * dt
    return {"x": f64(ins["x"]) + v1 * dt, "v": v1}


# -- all-pairs n-body ---------------------------------------------------------------
def nbody_inputs(n: int, rng: np.random.Generator) -> Inputs:
    """Gaussian positions (n, 3), masses in [0.5, 1.5), softening eps2 = 0.01."""
    return {
        "pos": _f32(rng.normal(size=(n, 3))),
        "mass": _f32(rng.uniform(0.5, 1.5, n)),
        "eps2": 0.01,
    }


def _nbody_rows(ins: Inputs) -> np.ndarray:
    n = len(ins["pos"])
    return np.linspace(0, n - 1, min(n, NBODY_CHECK_ROWS)).astype(np.int64)


def nbody_reference(ins: Inputs) -> Outputs:
    """Accelerations (Plummer softening) of the checked rows, in float64."""
    p = f64(ins["pos"])
    rows = _nbody_rows(ins)
    d = p[None, :, :] - p[rows, None, :]
    inv_r = 1.0 / np.sqrt(np.sum(d * d, axis=2) + ins["eps2"])
    return {"acc": np.einsum("ijk,ij->ik", d, f64(ins["mass"])[None, :] * inv_r**3)}


def _nbody_select(ins: Inputs, got: Outputs) -> Outputs:
    return {"acc": np.asarray(got["acc"]).reshape(-1, 3)[_nbody_rows(ins)]}


# -- 2D Jacobi stencil ------------------------------------------------------------------
def jacobi_inputs(n: int, rng: np.random.Generator) -> Inputs:
    """An n x n grid of values in [0, 1)."""
    return {"u": _f32(rng.uniform(0, 1, (n, n)))}


def jacobi_reference(ins: Inputs) -> Outputs:
    """One Jacobi sweep: interior points average their 4 neighbours, the edge is copied."""
    u = f64(ins["u"])
    out = u.copy()
    out[1:-1, 1:-1] = 0.25 * (u[:-2, 1:-1] + u[2:, 1:-1] + u[1:-1, :-2] + u[1:-1, 2:])
    return {"out": out}


# -- cloth: spring-mass grid ------------------------------------------------------------
CLOTH = {"spacing": 0.01, "stiffness": 1000.0, "inv_mass": 10.0, "dt": 1e-4}
#: (row, col) offsets of a particle's springs: 4 structural, 4 shear.
CLOTH_NEIGHBOURS = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1))


def cloth_inputs(g: int, rng: np.random.Generator) -> Inputs:
    """A g x g grid of particles (row-major, flattened to (g*g, 3)), slightly jittered."""
    h = CLOTH["spacing"]
    r, c = np.meshgrid(np.arange(g), np.arange(g), indexing="ij")
    x = np.stack([c * h, np.zeros_like(r, dtype=float), r * h], axis=-1).reshape(-1, 3)
    x = x + rng.uniform(-0.1 * h, 0.1 * h, x.shape)
    v = rng.uniform(-0.01, 0.01, x.shape)
    return {"x": _f32(x), "v": _f32(v), "grid": g, **CLOTH, "gravity": _f32([0.0, -9.8, 0.0])}


def cloth_reference(ins: Inputs) -> Outputs:
    """One semi-implicit Euler step with Hooke springs to the 8 neighbours, gathered."""
    g, h, k = ins["grid"], ins["spacing"], ins["stiffness"]
    x = f64(ins["x"]).reshape(g, g, 3)
    v = f64(ins["v"]).reshape(g, g, 3)
    force = np.zeros_like(x)
    for dr, dc in CLOTH_NEIGHBOURS:
        rest = h * np.hypot(dr, dc)
        # Neighbour positions where they exist; the particle itself (no force) elsewhere.
        nb = x.copy()
        rs, re = max(0, -dr), g - max(0, dr)
        cs, ce = max(0, -dc), g - max(0, dc)
        nb[rs:re, cs:ce] = x[rs + dr : re + dr, cs + dc : ce + dc]
        d = nb - x
        length = np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
        safe = np.where(length > 0, length, 1.0)
        force += np.where(length > 0, k * (length - rest) * d / safe, 0.0)
    v1 = v + (force * ins["inv_mass"] + f64(ins["gravity"])) * ins["dt"]
    x1 = x + v1 * ins["dt"]
    return {"x_out": x1.reshape(-1, 3), "v_out": v1.reshape(-1, 3)}


# -- launch overhead ------------------------------------------------------------------
#: Launches timed per repetition of the launch-overhead workloads.
LAUNCHES_PER_REP = 2000


def launch_inputs(n: int, rng: np.random.Generator) -> Inputs:
    """Two tiny arrays; the kernel (dim=1) does ``b[0] = a[0] + 1``."""
    return {"a": _f32(rng.uniform(0, 1, n)), "b": np.zeros(n, np.float32)}


def launch_reference(ins: Inputs) -> Outputs:
    b = f64(ins["b"]).copy()
    b[0] = f64(ins["a"])[0] + 1.0
    return {"b": b}


# -- device-to-device copy (the GPU's bandwidth yardstick) -----------------------------
def copy_inputs(n: int, rng: np.random.Generator) -> Inputs:
    """A source array x and a zeroed destination y."""
    return {"x": _f32(rng.uniform(-1, 1, n)), "y": np.zeros(n, np.float32)}


def copy_reference(ins: Inputs) -> Outputs:
    return {"y": f64(ins["x"])}


# -- the list ------------------------------------------------------------------------
_NBODY = dict(
    make_inputs=nbody_inputs, reference=nbody_reference, outputs=("acc",), select=_nbody_select
)
_LAUNCH = dict(
    size=16, quick_size=16, make_inputs=launch_inputs, reference=launch_reference,
    outputs=("b",), kind="launch", reps=7,
)  # fmt: skip

WORKLOADS: dict[str, Workload] = {
    w.name: w
    for w in [
        Workload("saxpy", "saxpy (2^24)", 2**24, 2**20, saxpy_inputs, saxpy_reference, 1e-6,
                 ("y",), reps=20),
        Workload("particles", "particles (2^22)", 2**22, 2**18, particles_inputs,
                 particles_reference, 1e-5, ("x", "v"), reps=20),
        Workload("nbody", "n-body (16384)", 16384, 2048, tolerance=1e-4, reps=5, **_NBODY),
        Workload("nbody_fast", "n-body fast math", 16384, 2048, tolerance=2e-3, reps=5,
                 fast_math=True, **_NBODY),
        Workload("jacobi", "jacobi (4096^2)", 4096, 1024, jacobi_inputs, jacobi_reference,
                 1e-6, ("out",), reps=20),
        Workload("cloth", "cloth (256^2)", 256, 64, cloth_inputs, cloth_reference, 1e-4,
                 ("x_out", "v_out"), reps=50),
        Workload("launch", "launch", tolerance=1e-6, **_LAUNCH),
        Workload("launch_prepared", "prepared launch", tolerance=1e-6, **_LAUNCH),
    ]
}  # fmt: skip

#: Rows only the GPU benchmark runs: saxpy at 2^26 (its GB/s is held to the copy's) and
#: the device-to-device copy of 2^26 floats (CuPy only: the bandwidth yardstick).
CUDA_WORKLOADS: dict[str, Workload] = {
    w.name: w
    for w in [
        Workload("saxpy_26", "saxpy (2^26)", 2**26, 2**22, saxpy_inputs, saxpy_reference, 1e-6,
                 ("y",), reps=20, impl="saxpy"),
        Workload("copy", "d2d copy (2^26)", 2**26, 2**22, copy_inputs, copy_reference, 0.0,
                 ("y",), reps=20),
    ]
}  # fmt: skip

#: Workloads measured in fresh processes (``harness.process_bench``), not as steps.
PROCESS_WORKLOADS = {
    "cold_compile": "cold start: process start to first n-body result, empty kernel cache",
    "compile": "compile alone: the n-body kernel's first launch minus a warm launch",
    "warm_start": "warm start: after import to first n-body result, kernel cache hit",
}

#: Extra rows: the STREAM triad bandwidth (Numba) and kdsl's n-body thread scaling.
EXTRA_WORKLOADS = {
    "triad": "STREAM triad a = b + s*c (2^24), the bandwidth saxpy is held to",
    "scaling": "kdsl n-body speedup from 1 to 2 threads (8192 bodies)",
}

#: The bodies of the cold/warm start n-body (small: the compile dominates).
START_BODIES = 1024
