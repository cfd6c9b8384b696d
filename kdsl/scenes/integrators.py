"""Integrators chosen by name, built from a few generic array kernels.

Every scene is ``y' = f(y)`` (order 1) or ``x'' = a(x, v)`` (order 2); the scene
launches ``f``/``a`` (``Scene.rhs``) and this module combines the results:

- ``explicit_euler``: ``x += h v; v += h a(x, v)`` (order 1: ``y += h f(y)``);
- ``symplectic_euler``: ``v += h a(x, v); x += h v`` (the seeds' ``integrate``);
- ``velocity_verlet``: half kick, drift, half kick; when the forces depend on the
  velocity, the end acceleration is taken at a predicted end velocity, which keeps
  the method second order;
- ``rk4``: the classic four-stage Runge-Kutta method;
- ``analytic``: no integration: the scene evaluates its closed form at ``t + h``
  (``Scene.evaluate``; the ocean surface);
- ``backward_euler``: one Newton step of backward Euler (exact for linear forces),
  its linear system ``(I - h^2 J_x - h J_v) dv = h a(x + h v, v)`` (order 1:
  ``(I - h J) dy = h f(y)``) solved by ``jacobi_iters`` Jacobi iterations (a scene
  parameter, default 40) with the scene's ``jvp`` and ``jacobian_diag``.

The kernels are written with the public API of whichever ``wp`` the scene is bound
to, so they run under Warp too.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables
# (``real``, ``vec3``), which string annotations cannot reach.

from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

#: Jacobi iterations of the implicit solve unless the scene's parameters say otherwise.
JACOBI_ITERS = 40


@cache
def make_integrator_kernels(wp: ModuleType, dof: Any, real: Any) -> SimpleNamespace:
    """The update kernels for dof type ``dof`` (a float or vector of ``real``)."""
    # Array annotations by element type, named once so the kernel signatures stay short.
    RealArray = wp.array(dtype=real)
    DofArray = wp.array(dtype=dof)

    @wp.kernel(module="unique")
    def axpy(out: DofArray, x: DofArray, a: real, y: DofArray):
        i = wp.tid()
        out[i] = x[i] + a * y[i]

    @wp.kernel(module="unique")
    def rk4_combine(
        out: DofArray, x: DofArray, h6: real, k1: DofArray, k2: DofArray, k3: DofArray, k4: DofArray
    ):
        i = wp.tid()
        out[i] = x[i] + h6 * (k1[i] + real(2.0) * (k2[i] + k3[i]) + k4[i])

    @wp.kernel(module="unique")
    def jacobi_update(out: DofArray, z: DofArray, b: DofArray, jz: DofArray, diag: RealArray):
        # (I - C) z = b with C = cx J_x + cv J_v: z += (b - z + C z) / (1 - diag(C))
        i = wp.tid()
        out[i] = z[i] + (b[i] - z[i] + jz[i]) / (real(1.0) - diag[i])

    return SimpleNamespace(axpy=axpy, rk4_combine=rk4_combine, jacobi_update=jacobi_update)


class Stepper:
    """Runs one scene's integrator: its scratch arrays and the launches of one step."""

    def __init__(self, scene: Any) -> None:
        self.scene = scene
        self.k = make_integrator_kernels(scene.wp, scene.dof_dtype, scene.real)
        self._scratch: dict[str, Any] = {}
        self.step = getattr(self, f"_{scene.integrator}_{scene.order}")

    def _tmp(self, name: str) -> Any:
        """A scratch dof array, allocated once."""
        a = self._scratch.get(name)
        if a is None:
            a = self._scratch[name] = self.scene.array()
        return a

    def _axpy(self, out: Any, x: Any, a: float, y: Any) -> None:
        s = self.scene
        s.launch(self.k.axpy, s.n, [out, x, s.real(a), y])

    # ------------------------------------------------------------------ order 2

    def _explicit_euler_2(self, h: float) -> None:
        s, a = self.scene, self._tmp("a")
        s.rhs(s.x, s.v, a)
        self._axpy(s.x, s.x, h, s.v)
        self._axpy(s.v, s.v, h, a)

    def _symplectic_euler_2(self, h: float) -> None:
        s, a = self.scene, self._tmp("a")
        s.rhs(s.x, s.v, a)
        self._axpy(s.v, s.v, h, a)
        self._axpy(s.x, s.x, h, s.v)

    def _velocity_verlet_2(self, h: float) -> None:
        s, a, vh = self.scene, self._tmp("a"), self._tmp("vh")
        s.rhs(s.x, s.v, a)
        self._axpy(vh, s.v, 0.5 * h, a)
        self._axpy(s.x, s.x, h, vh)
        s.rhs(s.x, vh, a)
        if s.velocity_dependent:
            vp = self._tmp("vp")
            self._axpy(vp, vh, 0.5 * h, a)
            s.rhs(s.x, vp, a)
        self._axpy(s.v, vh, 0.5 * h, a)

    def _rk4_2(self, h: float) -> None:
        s = self.scene
        xs = [s.x] + [self._tmp(f"x{i}") for i in (2, 3, 4)]
        vs = [s.v] + [self._tmp(f"v{i}") for i in (2, 3, 4)]
        acc = [self._tmp(f"a{i}") for i in (1, 2, 3, 4)]
        for i, c in enumerate((0.5 * h, 0.5 * h, h)):
            s.rhs(xs[i], vs[i], acc[i])
            self._axpy(xs[i + 1], s.x, c, vs[i])
            self._axpy(vs[i + 1], s.v, c, acc[i])
        s.rhs(xs[3], vs[3], acc[3])
        h6 = s.real(h / 6.0)
        s.launch(self.k.rk4_combine, s.n, [s.x, s.x, h6, *vs])
        s.launch(self.k.rk4_combine, s.n, [s.v, s.v, h6, *acc])

    def _backward_euler_2(self, h: float) -> None:
        s, xp, b = self.scene, self._tmp("xp"), self._tmp("b")
        self._axpy(xp, s.x, h, s.v)
        s.rhs(xp, s.v, b)
        self._axpy(b, self._zeros(), h, b)  # b = h a(x + h v, v)
        dv = self._jacobi(xp, s.v, b, h * h, h)
        self._axpy(s.v, s.v, 1.0, dv)
        self._axpy(s.x, s.x, h, s.v)

    # ------------------------------------------------------------------ order 1

    def _explicit_euler_1(self, h: float) -> None:
        s, f = self.scene, self._tmp("f")
        s.rhs(s.x, None, f)
        self._axpy(s.x, s.x, h, f)

    def _rk4_1(self, h: float) -> None:
        s = self.scene
        ys = [s.x] + [self._tmp(f"y{i}") for i in (2, 3, 4)]
        ks = [self._tmp(f"k{i}") for i in (1, 2, 3, 4)]
        for i, c in enumerate((0.5 * h, 0.5 * h, h)):
            s.rhs(ys[i], None, ks[i])
            self._axpy(ys[i + 1], s.x, c, ks[i])
        s.rhs(ys[3], None, ks[3])
        s.launch(self.k.rk4_combine, s.n, [s.x, s.x, s.real(h / 6.0), *ks])

    def _backward_euler_1(self, h: float) -> None:
        s, b = self.scene, self._tmp("b")
        s.rhs(s.x, None, b)
        self._axpy(b, self._zeros(), h, b)  # b = h f(y)
        dy = self._jacobi(s.x, None, b, h, 0.0)
        self._axpy(s.x, s.x, 1.0, dy)

    def _analytic_1(self, h: float) -> None:
        self.scene.evaluate(self.scene.t + h)

    # ------------------------------------------------------------------ the solve

    def _zeros(self) -> Any:
        z = self._scratch.get("zeros")
        if z is None:
            z = self._scratch["zeros"] = self.scene.array()
        return z

    def _jacobi(self, x: Any, v: Any, b: Any, cx: float, cv: float) -> Any:
        """``z`` with ``(I - cx J_x - cv J_v) z = b``, by Jacobi iterations from ``z = 0``."""
        s = self.scene
        diag = self._scratch.get("diag")
        if diag is None:
            diag = self._scratch["diag"] = s.scalars(s.n)
        z, z2, jz = self._tmp("z"), self._tmp("z2"), self._tmp("jz")
        # From z = 0, K iterations give z = (I - G^K) A^-1 b with G the Jacobi iteration
        # matrix (|eigenvalues| < 1 for these diagonally dominant systems): every mode
        # is damped, so the truncated solve keeps backward Euler stable at any dt. From
        # z = b, the slow modes (G's eigenvalues near -1 at large dt) would keep b's
        # unscaled size and blow up.
        z.zero_()
        s.jacobian_diag(x, v, cx, cv, diag)
        for _ in range(int(s.params.get("jacobi_iters", JACOBI_ITERS))):
            s.jvp(x, v, z, cx, cv, jz)
            s.launch(self.k.jacobi_update, s.n, [z2, z, b, jz, diag])
            z, z2 = z2, z
        return z
