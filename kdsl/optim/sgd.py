"""``SGD``: Warp 1.19's stochastic gradient descent (``warp.optim.SGD``) over kdsl arrays."""

from __future__ import annotations

from typing import Any

from kdsl.optim.common import (
    OptimError,
    check_like,
    check_number,
    check_params,
    fitted,
    flat,
    list_of,
    value_type,
    zero_all,
)
from kdsl.optim.kernels import sgd_kernel
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch


class SGD:
    """Gradient descent with momentum, dampening, Nesterov and weight decay, as Warp's.

    Each step, for every parameter array ``p`` with gradient ``g`` and momentum buffer
    ``b`` (PyTorch's formulation)::

        g = g + weight_decay p                          if weight_decay != 0
        b = g on the first step, else momentum b + (1 - dampening) g
        g = g + momentum b if nesterov else b           if momentum != 0
        p = p - lr g

    then ``t += 1``. ``params`` is a list of kdsl arrays of ``float16``, ``float32``,
    ``float64`` or vectors or matrices of them, or None (see ``set_params``); the buffers
    ``b`` have the parameter's dtype (``float16`` is updated in ``float32`` and rounded
    back). As in Warp, ``nesterov`` is meant for ``momentum > 0`` and ``dampening == 0``
    but is not refused otherwise (with ``momentum == 0`` it has no effect).
    ``backend`` (a kdsl addition) names the backend the kernel runs on.
    """

    def __init__(
        self,
        params: list[array] | None = None,
        lr: float = 0.001,
        momentum: float = 0.0,
        dampening: float = 0.0,
        weight_decay: float = 0.0,
        nesterov: bool = False,
        *,
        backend: Any = None,
    ) -> None:
        self.b: list[array | None] = []  # momentum buffers
        self.backend = backend
        self.set_params(params)
        self.lr = check_number("SGD", "lr", lr)
        self.momentum = check_number("SGD", "momentum", momentum)
        self.dampening = check_number("SGD", "dampening", dampening)
        self.weight_decay = check_number("SGD", "weight_decay", weight_decay)
        self.nesterov = nesterov
        self.t = 0

    def set_params(self, params: list[array] | None) -> None:
        """Set the arrays to optimize; momentum buffers are (re)allocated where they no
        longer fit (shape or dtype) and moved where the parameter moved, as in Warp."""
        self.params = check_params("SGD", params, quats=True)
        if not self.params:
            return
        self.b = fitted(self.b, self.params, lambda p: p.dtype)

    def reset_internal_state(self) -> None:
        """Zero the momentum buffers and the step count."""
        zero_all(self.b)
        self.t = 0

    def step(self, grad: list[array]) -> None:
        """Apply one SGD step with ``grad``, one gradient array per parameter array."""
        if self.params is None:
            raise OptimError("SGD parameters must be set before calling step(), got None")
        grads = list_of("SGD", "grad", grad, len(self.params))
        for i, p in enumerate(self.params):
            SGD.step_detail(
                grads[i], self.b[i], self.lr, self.momentum, self.dampening, self.weight_decay,
                self.nesterov, self.t, p, backend=self.backend,
            )  # fmt: skip
        self.t = self.t + 1

    @staticmethod
    def step_detail(
        g: array, b: array, lr: float, momentum: float, dampening: float, weight_decay: float,
        nesterov: bool, t: int, params: array, *, backend: Any = None,
    ) -> None:  # fmt: skip
        """One SGD update of ``params`` in place, with momentum buffer ``b`` and step ``t``."""
        (params,) = check_params("SGD", [params], quats=True)
        check_like("SGD", "gradient", g, params)
        check_like("SGD", "momentum buffer", b, params)
        scalars = [check_number("SGD", n, x) for n, x in
                   (("lr", lr), ("momentum", momentum), ("dampening", dampening),
                    ("weight_decay", weight_decay))]  # fmt: skip
        flat_p = flat(params, "SGD params")
        launch(
            sgd_kernel(value_type(params.dtype, quats=True)), dim=flat_p.shape[0],
            inputs=[flat(g, "SGD gradient"), flat(b, "SGD momentum buffer"), *scalars,
                    int(bool(nesterov)), int(t), flat_p],
            device=params.device, backend=backend,
        )  # fmt: skip
