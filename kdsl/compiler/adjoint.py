"""The adjoint module of a kernel: its forward function plus the adjoint the pass derives.

The ``adjoint`` pass (``kdsl.passes.adjoint``) adds the kernel's adjoint function (and,
for loops with run-time trip counts, a tape-counting function); this module runs it
between the pipelines of ``kdsl.compiler.pipelines``.
"""

from __future__ import annotations

from typing import Any

from kdsl.compiler.pipelines import POST_ADJOINT_PIPELINE, PRE_ADJOINT_PIPELINE
from kdsl.ir import Module
from kdsl.passes import run_pipeline
from kdsl.passes.adjoint import AdjointPass


def adjoint_module(kernel: Any) -> Module:
    """``kernel``'s optimized module with its adjoint (and tape counter) functions added.

    Calls to functions with custom gradients stay calls until the adjoint exists; the
    adjoint functions are then simplified and stripped of unread tapes (``tape-dce``).
    """
    module = kernel.build_module()
    run_pipeline(module, PRE_ADJOINT_PIPELINE)
    AdjointPass(kernel.key).apply(module)
    run_pipeline(module, POST_ADJOINT_PIPELINE)
    return module
