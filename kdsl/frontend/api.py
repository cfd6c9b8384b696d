"""Public names of the frontend (decorators, kernel-language builtins).

``import kdsl as wp`` gets ``wp.kernel``, ``wp.func``, ``wp.tid``, ``wp.static``,
``wp.constant`` and every builtin of ``kdsl.frontend.builtins.BUILTINS``
(``wp.sin``, ``wp.dot``, ``wp.atomic_add``, ...).
"""

from kdsl.frontend.builtins import BUILTINS, Builtin
from kdsl.frontend.kernel import Function, Kernel, func, kernel
from kdsl.frontend.static import constant, static

globals().update(BUILTINS)

__all__ = [
    "Builtin", "Function", "Kernel", "constant", "func", "kernel", "static",
    *sorted(BUILTINS),
]  # fmt: skip
