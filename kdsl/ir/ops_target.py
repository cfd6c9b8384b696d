"""``kd.target_has``: whether the backend compiling a kernel takes a named code path.

Library code that keeps two ways of doing one thing, each the faster on some targets,
asks the target with this op instead of a run-time flag: ``kd.target_has {feature =
"wide-tree"}`` is a bool that each backend lowers to a constant (``true`` where its
``TARGET_FEATURES`` lists the feature), so the code behind an ``scf.if`` on it is
compiled only where it can run, and a GPU kernel does not carry (and allocate
registers for) a CPU-only path. No pass folds it (its value is the backend's, not the
IR's); the interpreter, the reference, takes every path (``INTERP_FEATURES``) so that
tests run each.

Features (``FEATURES``): ``"wide-tree"``, the 4-wide BVH walks of the mesh point
queries (``kdsl.stdlib.mesh_wide``): the cpu backend and the interpreter.
"""

from __future__ import annotations

import numpy as np

from kdsl.ir.catalog import CATALOG, PURE
from kdsl.ir.types import BOOL

#: The feature names a ``kd.target_has`` may ask for (see the module docstring).
FEATURES = ("wide-tree",)
#: The features the interpreter has: all of them.
INTERP_FEATURES = frozenset(FEATURES)


def _verify(op) -> None:
    if op.operands:
        raise TypeError("kd.target_has takes no operands")
    if len(op.results) != 1 or op.results[0].type != BOOL:
        raise TypeError("kd.target_has gives one bool")
    if op.attrs.get("feature") not in FEATURES:
        raise TypeError(f"kd.target_has feature must be one of {FEATURES}, not "
                        f"{op.attrs.get('feature')!r}")  # fmt: skip


def _interp(ctx, op):
    return np.bool_(op.attrs["feature"] in INTERP_FEATURES)


def _no_fold(op, args):
    """Never folded: the answer is the backend's (see the module docstring)."""
    return None


TARGET_HAS = CATALOG.define(
    "kd.target_has",
    "Whether the backend compiling the kernel takes the code path ``feature`` (a name "
    f"from {FEATURES}): a bool each backend lowers to a constant; never folded by a pass "
    "(``kdsl.ir.ops_target``).",
    traits=frozenset({PURE}), verifier=_verify, interp=_interp, folder=_no_fold,
    required_attrs=("feature",), example='%0 = kd.target_has {feature = "wide-tree"} : bool',
    group="target",
)  # fmt: skip

__all__ = ["FEATURES", "INTERP_FEATURES", "TARGET_HAS"]
