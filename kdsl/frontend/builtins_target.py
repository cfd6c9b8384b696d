"""Target queries for library code: ``target_has_wide_tree()`` (IR: ``kd.target_has``).

Not a user builtin (no table lists it, docs/builtins.md does not show it): the
standard library calls the ``Builtin`` object itself where it keeps a code path that
only some backends should compile (``kdsl.ir.ops_target``).
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import Builtin
from kdsl.ir.types import BOOL


def _target_has(feature: str):
    """The lowering of a query for ``feature``: a ``kd.target_has`` bool."""

    def lower(em, args: list[Any], node, **kw: Any) -> Any:
        if args or kw:
            raise em.error(KdslTypeError, "a target query takes no arguments", node)
        return em.emit_typed("kd.target_has", [], BOOL, node, feature=feature)

    return lower


TARGET_HAS_WIDE_TREE = Builtin(
    "target_has_wide_tree",
    _target_has("wide-tree"),
    "``target_has_wide_tree()``: whether the backend compiling the kernel walks meshes' "
    "4-wide trees (``kd.target_has {feature = \"wide-tree\"}``: the cpu backend and the "
    "interpreter); a compile-time constant of the backend, so the other path is not "
    "compiled.",
    (0, 0),
    "target",
)

__all__ = ["TARGET_HAS_WIDE_TREE"]
