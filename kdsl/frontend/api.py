"""Public names of the frontend (decorators, kernel-language builtins).

``import kdsl as wp`` gets ``wp.kernel``, ``wp.func``, ``wp.tid``, ``wp.static``,
``wp.constant``, the constants (``wp.pi``, ``wp.tau``...), ``wp.func_grad``/``wp.func_replay``/``wp.adjoint`` (custom
gradients) and every builtin of ``kdsl.frontend.builtins.BUILTINS``
(``wp.sin``, ``wp.dot``, ``wp.atomic_add``, ...).
"""

from kdsl.frontend.builtins import BUILTINS
from kdsl.frontend.builtins_base import Builtin
from kdsl.frontend.constants import *  # noqa: F403
from kdsl.frontend.constants import __all__ as _constant_names
from kdsl.frontend.custom_grad import adjoint, func_grad, func_replay
from kdsl.frontend.generic import Float, Int
from kdsl.frontend.grad import grad
from kdsl.frontend.inout import inout
from kdsl.frontend.kernel import Function, Kernel, func, kernel, overload
from kdsl.frontend.static import constant, static

globals().update(BUILTINS)

__all__ = [
    "Builtin", "Float", "Function", "Int", "Kernel", "adjoint", "constant", "func", "func_grad", "func_replay",
    "grad", "inout", "kernel", "overload", "static",
    *_constant_names,
    *sorted(BUILTINS),
]  # fmt: skip
