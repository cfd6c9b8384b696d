"""The update kernels of ``Adam`` and ``SGD``: kdsl kernels, one instance per parameter type.

Each factory is cached on the parameter's IR type and closes over three classes: ``P``,
the parameter's element type; ``C``, the type the update computes in (``P`` with
``float16`` widened to ``float32``); and ``S``, the scalar type of the hyperparameters
(``float64`` for ``float64`` elements, else ``float32`` as Warp's ``float``). The
formulas are Warp 1.19's, operation for operation, so a ``float32`` step rounds as
Warp's does. (No ``from __future__ import annotations`` here: the annotations name
classes of the factory's closure and are evaluated where the kernel is defined.)
"""

from functools import cache

from kdsl.frontend.api import cw_div, cw_mul, kernel, sqrt, static, tid
from kdsl.frontend.api import pow as kpow
from kdsl.ir import types as T
from kdsl.optim.common import compute_type, scalar_class
from kdsl.runtime.array import array
from kdsl.types import class_of


@cache
def adam_kernel(t: T.Type):
    """Adam's step for arrays of ``t``: moments ``m``, ``v`` of the compute type."""
    P, C, S = class_of(t), class_of(compute_type(t)), scalar_class(t)

    # Vector and matrix elements square and divide component-wise.
    composite = not isinstance(t, T.ScalarType)

    @kernel
    def adam_step(
        g: array(dtype=P), m: array(dtype=C), v: array(dtype=C), lr: S, beta1: S,
        beta2: S, t: S, eps: S, params: array(dtype=P),
    ):  # fmt: skip
        i = tid()
        gi = C(g[i])
        m[i] = beta1 * m[i] + (1.0 - beta1) * gi
        if static(composite):
            v[i] = beta2 * v[i] + (1.0 - beta2) * cw_mul(gi, gi)
        else:
            v[i] = beta2 * v[i] + (1.0 - beta2) * gi * gi
        mhat = m[i] / (1.0 - kpow(beta1, t + 1.0))
        vhat = v[i] / (1.0 - kpow(beta2, t + 1.0))
        if static(composite):
            params[i] = params[i] - P(lr * cw_div(mhat, sqrt(vhat) + C(eps)))
        else:
            params[i] = params[i] - P(lr * mhat / (sqrt(vhat) + eps))

    return adam_step


@cache
def sgd_kernel(t: T.Type):
    """SGD's step for arrays of ``t``, with a momentum buffer ``b`` of ``t``."""
    P, C, S = class_of(t), class_of(compute_type(t)), scalar_class(t)

    @kernel
    def sgd_step(
        g: array(dtype=P), b: array(dtype=P), lr: S, momentum: S, dampening: S,
        weight_decay: S, nesterov: int, t: int, params: array(dtype=P),
    ):  # fmt: skip
        i = tid()
        gt = C(g[i])
        if weight_decay != 0.0:
            gt = gt + weight_decay * C(params[i])
        if momentum != 0.0:
            bt = C(b[i])
            if t > 0:
                bt = momentum * bt + (1.0 - dampening) * gt
            else:
                bt = gt
            if nesterov == 1:
                gt = gt + momentum * bt
            else:
                gt = bt
            b[i] = P(bt)
        params[i] = P(C(params[i]) - lr * gt)

    return sgd_step
