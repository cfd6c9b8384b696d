"""``kdsl.optim``: Warp's gradient-descent optimizers over kdsl arrays.

``Adam`` and ``SGD`` take Warp 1.19's constructor arguments and defaults, keep its
attributes (``lr``, ``t``, the moment buffers ``m``/``v`` and ``b``) and update in place
with ``step(grad)``; the updates are kdsl kernels and run on each parameter's device.
Bad arguments raise ``OptimError`` (a ``KdslError`` and a ``RuntimeError``), with
``OptimTypeError`` and ``OptimShapeError`` for gradients of the wrong dtype or shape
(also ``TypeError`` and ``ValueError``, as Warp raises). Warp's ``warp.optim.linear``
(iterative sparse solvers) is not provided: it is built on ``warp.sparse``, which kdsl
lacks (docs/autodiff.md, "Optimizers").
"""

from kdsl.optim.adam import Adam
from kdsl.optim.common import OptimError, OptimShapeError, OptimTypeError
from kdsl.optim.sgd import SGD

__all__ = ["SGD", "Adam", "OptimError", "OptimShapeError", "OptimTypeError"]
