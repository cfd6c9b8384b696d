"""The scene base class: parameters, state, a step by a named integrator, a reference.

A scene subclass (one file per scene, see ``kdsl/scenes/__init__.py``) declares:

- ``name``, ``summary``, ``order`` (1: ``y' = f(y)``; 2: ``x'' = a(x, v)``),
  ``integrators`` (the names it supports, the first is the default), ``defaults``
  (its parameters), ``default_dt``, ``default_steps``;
- ``make_kernels(wp, real)``: its kernels, built with the public API of ``wp`` and the
  float type ``real`` (``wp.float16``/``float32``/``float64``);
- ``initial_state()``: float64 NumPy ``x0`` (and ``v0`` for order 2), flat, one row
  per degree of freedom (``(n,)`` scalars or ``(n, 3)`` vectors);
- ``rhs(x, v, out)``: launches writing ``f(x)`` (order 1) or ``a(x, v)`` (order 2);
- ``jvp(x, v, z, cx, cv, out)`` and ``jacobian_diag(x, v, cx, cv, out)`` for the
  implicit integrator: ``out = cx * (d rhs/dx) z + cv * (d rhs/dv) z`` and the
  diagonal of that operator (one ``real`` per dof);
- ``reference(t)``: the float64 solution ``x(t)`` (closed form or a float64 run);
- ``energy(x, v)``: a float64 energy on the host (None where meaningless);
- optionally ``theory_dt_limit(integrator)``: the largest stable dt theory gives.

The base class owns the arrays, the integrator (``kdsl.scenes.integrators``), the
clock and the error measure; the scene only describes its physics.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import Any, ClassVar

import numpy as np

from kdsl.scenes.binding import SceneError, is_kdsl

#: Precision name -> the ``wp`` attribute of its float type, and the backend capability.
PRECISIONS = {"f16": ("float16", "fp16"), "f32": ("float32", "fp32"), "f64": ("float64", "fp64")}
#: Every integrator, in the order tables list them.
ALL_INTEGRATORS = ("explicit_euler", "symplectic_euler", "velocity_verlet", "rk4", "backward_euler")
#: The integrators of a first-order system (the others need ``x'' = a(x, v)``).
FIRST_ORDER_INTEGRATORS = ("explicit_euler", "rk4", "backward_euler")
#: Expected convergence order of each integrator (the tests check it, loosely).
ORDER = {"explicit_euler": 1, "symplectic_euler": 1, "velocity_verlet": 2, "rk4": 4,
         "backward_euler": 1}  # fmt: skip


def check_choice(what: str, value: str, choices: tuple[str, ...] | list[str]) -> str:
    """``value`` if it is one of ``choices``, else a ``SceneError`` listing them."""
    if value not in choices:
        raise SceneError(f"unknown {what} {value!r} (choices: {', '.join(choices)})")
    return value


def check_dt(dt: float) -> float:
    """``dt`` as a float if it is finite and positive, else a ``SceneError``."""
    dt = float(dt)
    if not math.isfinite(dt) or dt <= 0.0:
        raise SceneError(f"dt must be a finite number > 0, not {dt!r}")
    return dt


class Scene:
    """A simulation scene (see the module docstring for what a subclass declares)."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    order: ClassVar[int] = 2
    integrators: ClassVar[tuple[str, ...]] = ALL_INTEGRATORS
    defaults: ClassVar[dict[str, Any]] = {}
    default_dt: ClassVar[float] = 1e-3
    default_steps: ClassVar[int] = 1000
    #: The forces depend on velocity (velocity Verlet then corrects its end velocity).
    velocity_dependent: ClassVar[bool] = False
    #: What ``error()`` compares, for reports.
    error_what: ClassVar[str] = "max |x - x_ref| / max |x_ref|"

    def __init__(
        self,
        wp: ModuleType,
        precision: str = "f32",
        integrator: str | None = None,
        device: str = "cpu",
        backend: str | None = None,
        **params: Any,
    ) -> None:
        from kdsl.scenes.integrators import Stepper

        self.wp = wp
        self.precision = check_choice("precision", precision, list(PRECISIONS))
        self.integrator = check_choice(
            f"integrator for scene {self.name!r}", integrator or self.integrators[0],
            self.integrators,
        )  # fmt: skip
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            raise SceneError(f"scene {self.name!r} has no parameter {unknown[0]!r} "
                             f"(parameters: {', '.join(sorted(self.defaults)) or 'none'})")  # fmt: skip
        self.params = {**self.defaults, **params}
        self.device = device
        # kdsl's launch takes a backend (interp on the cpu); Warp's has no such argument.
        self.launch_options = {"backend": backend} if backend and is_kdsl(wp) else {}
        self.real = getattr(wp, PRECISIONS[self.precision][0])
        self.setup()
        self.k = self.make_kernels(wp, self.real)
        x0, v0 = self.initial_state()
        self.dof_shape = x0.shape
        self.dof_dtype = self.real if x0.ndim == 1 else wp.types.vector(3, self.real)
        self.x = self.array(x0)
        self.v = self.array(v0) if self.order == 2 else None
        self.t = 0.0
        self.stepper = Stepper(self)

    # ------------------------------------------------------------------ for subclasses

    def setup(self) -> None:
        """Derive host-side constants from ``self.params`` (before the kernels)."""

    def int_param(self, name: str, minimum: int, why: str = "") -> int:
        """Parameter ``name`` as an int, a ``SceneError`` when it is below ``minimum``
        (``why``, if given, says why in the message)."""
        n = int(self.params[name])
        if n < minimum:
            reason = f" ({why})" if why else ""
            raise SceneError(f"{self.name} needs {name} >= {minimum}{reason}, not {n}")
        return n

    def make_kernels(self, wp: ModuleType, real: Any) -> Any:
        """The scene's kernels for ``wp`` and float type ``real`` (a namespace)."""
        raise NotImplementedError

    def initial_state(self) -> tuple[np.ndarray, np.ndarray | None]:
        """float64 ``x0`` and ``v0`` (None for a first-order scene)."""
        raise NotImplementedError

    def rhs(self, x: Any, v: Any, out: Any) -> None:
        """Launch kernels writing ``f(x)`` or ``a(x, v)`` into ``out``."""
        raise NotImplementedError

    def jvp(self, x: Any, v: Any, z: Any, cx: float, cv: float, out: Any) -> None:
        """``out = cx * J_x z + cv * J_v z`` (the implicit integrator's operator)."""
        raise SceneError(f"scene {self.name!r} has no Jacobian (no implicit integrator)")

    def jacobian_diag(self, x: Any, v: Any, cx: float, cv: float, out: Any) -> None:
        """The diagonal of ``cx * J_x + cv * J_v``, one ``real`` per dof."""
        raise SceneError(f"scene {self.name!r} has no Jacobian (no implicit integrator)")

    def reference(self, t: float) -> np.ndarray:
        """The float64 reference ``x(t)``."""
        raise NotImplementedError

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float | None:
        """The energy of a state (float64, on the host); None where it means nothing."""
        return None

    def stability_measure(self, x: np.ndarray, v: np.ndarray | None) -> float:
        """What must stay bounded for a run to count as stable (default: the energy)."""
        e = self.energy(x, v)
        return abs(e) if e is not None else float(np.max(np.abs(x)))

    def theory_dt_limit(self, integrator: str) -> float | None:
        """The largest stable dt by theory (math.inf: unconditionally stable; None: unknown)."""
        return None

    def picture(self, x: np.ndarray) -> Any:
        """What ``kdsl scene run --render/--usd`` draws for state ``x`` (a float64 copy).

        A ``kdsl.scenes.render.Picture``. Default: 3-vector dofs as points; scalar dofs
        as a graph (index across, value up). Scenes with a surface or obstacles override it.
        """
        from kdsl.scenes import render

        return render.Picture(x) if x.ndim == 2 else render.graph(x, render.height_scale(self))

    # ------------------------------------------------------------------ for everyone

    def launch(self, kernel: Any, dim: Any, inputs: list[Any]) -> None:
        """``wp.launch`` on the scene's device (and kdsl backend, if one was named)."""
        self.wp.launch(kernel, dim=dim, inputs=inputs, device=self.device, **self.launch_options)

    def array(self, values: np.ndarray | None = None, shape: tuple | None = None) -> Any:
        """A dof array on the scene's device: a copy of ``values``, or zeros."""
        dtype = getattr(self, "dof_dtype", self.real)
        if values is None:
            return self.wp.zeros(shape or self.dof_shape[:1], dtype=dtype, device=self.device)
        return self.wp.array(np.asarray(values), dtype=dtype, device=self.device)

    def scalars(self, n: int) -> Any:
        """``n`` zeros of the float type on the scene's device."""
        return self.wp.zeros(n, dtype=self.real, device=self.device)

    @property
    def n(self) -> int:
        """The number of degrees of freedom (array length)."""
        return int(self.dof_shape[0])

    def reset(self) -> None:
        """Back to the initial state at t = 0."""
        x0, v0 = self.initial_state()
        self.x.assign(self.wp.array(x0, dtype=self.dof_dtype, device=self.device))
        if self.v is not None:
            self.v.assign(self.wp.array(v0, dtype=self.dof_dtype, device=self.device))
        self.t = 0.0

    def step(self, dt: float) -> None:
        """Advance by ``dt`` with the scene's integrator."""
        self.stepper.step(dt)
        self.t += dt

    def state(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The current state as float64 NumPy arrays."""
        x = self.x.numpy().astype(np.float64)
        return x, (self.v.numpy().astype(np.float64) if self.v is not None else None)

    def error(self) -> float:
        """The error of the current state against ``reference(self.t)`` (see ``error_what``)."""
        x, _ = self.state()
        ref = self.reference(self.t)
        scale = max(float(np.max(np.abs(ref))), 1e-300)
        return float(np.max(np.abs(x - ref))) / scale
