"""``Adam``: Warp 1.19's Adam optimizer (``warp.optim.Adam``) over kdsl arrays."""

from __future__ import annotations

from typing import Any

from kdsl.optim.common import (
    OptimError,
    check_buffer,
    check_like,
    check_number,
    check_params,
    compute_type,
    fitted,
    flat,
    list_of,
    value_type,
    zero_all,
)
from kdsl.optim.kernels import adam_kernel
from kdsl.runtime.array import array
from kdsl.runtime.launch import launch
from kdsl.types import class_of


class Adam:
    """Adaptive Moment Estimation, with Warp's constructor, attributes and ``step(grad)``.

    Each step, for every parameter array ``p`` with gradient ``g`` (componentwise for
    vectors and matrices)::

        m = beta1 m + (1 - beta1) g
        v = beta2 v + (1 - beta2) g^2
        p = p - lr (m / (1 - beta1^(t+1))) / (sqrt(v / (1 - beta2^(t+1))) + eps)

    then ``t += 1``. ``params`` is a list of kdsl arrays of ``float16``, ``float32``,
    ``float64`` or vectors or matrices of them (Warp: ``float16``, ``float32``,
    ``vec3``), or None (set them later with ``set_params``). The moments ``m`` and ``v``
    have the parameter's type, with ``float16`` widened to ``float32``. ``backend`` (a
    kdsl addition) names the backend the update kernels run on (``"interp"``...), as in
    ``kdsl.launch``; by default the device's.
    """

    def __init__(
        self,
        params: list[array] | None = None,
        lr: float = 0.001,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-08,
        *,
        backend: Any = None,
    ) -> None:
        try:
            beta1, beta2 = betas
        except (TypeError, ValueError):
            raise OptimError(f"Adam betas must be a pair (beta1, beta2), got {betas!r}") from None
        self.m: list[array | None] = []  # first moments
        self.v: list[array | None] = []  # second moments
        self.backend = backend
        self.set_params(params)
        self.lr = check_number("Adam", "lr", lr)
        self.beta1 = check_number("Adam", "beta1", beta1)
        self.beta2 = check_number("Adam", "beta2", beta2)
        self.eps = check_number("Adam", "eps", eps)
        self.t = 0

    def set_params(self, params: list[array] | None) -> None:
        """Set the arrays to optimize; moment buffers are (re)allocated where they no
        longer fit (shape or dtype) and moved where the parameter moved, as in Warp."""
        self.params = check_params("Adam", params)
        if not self.params:
            return

        def moment_type(p: array) -> type:
            return class_of(compute_type(value_type(p.dtype)))

        self.m = fitted(self.m, self.params, moment_type)
        self.v = fitted(self.v, self.params, moment_type)

    def reset_internal_state(self) -> None:
        """Zero the moment buffers and the step count."""
        zero_all([*self.m, *self.v])
        self.t = 0

    def step(self, grad: list[array]) -> None:
        """Apply one Adam step with ``grad``, one gradient array per parameter array."""
        if self.params is None:
            raise OptimError("Adam parameters must be set before calling step(), got None")
        grads = list_of("Adam", "grad", grad, len(self.params))
        lr = check_number("Adam", "lr", self.lr)
        for i, p in enumerate(self.params):
            Adam.step_detail(
                grads[i], self.m[i], self.v[i], lr, self.beta1, self.beta2, self.t, self.eps, p,
                backend=self.backend,
            )  # fmt: skip
        self.t = self.t + 1

    @staticmethod
    def step_detail(
        g: array, m: array, v: array, lr: float, beta1: float, beta2: float, t: float,
        eps: float, params: array, *, backend: Any = None,
    ) -> None:  # fmt: skip
        """One Adam update of ``params`` in place, with moments ``m``, ``v`` and step ``t``."""
        (params,) = check_params("Adam", [params])
        pt = value_type(params.dtype)
        check_like("Adam", "gradient", g, params)
        moment_dtype = class_of(compute_type(pt))
        check_buffer("Adam", "first moment m", m, params, moment_dtype)
        check_buffer("Adam", "second moment v", v, params, moment_dtype)
        scalars = [check_number("Adam", n, x) for n, x in
                   (("lr", lr), ("beta1", beta1), ("beta2", beta2), ("t", t))]  # fmt: skip
        flat_p = flat(params, "Adam params")
        launch(
            adam_kernel(pt), dim=flat_p.shape[0],
            inputs=[flat(g, "Adam gradient"), flat(m, "Adam m"), flat(v, "Adam v"), *scalars,
                    check_number("Adam", "eps", eps), flat_p],
            device=params.device, backend=backend,
        )  # fmt: skip
