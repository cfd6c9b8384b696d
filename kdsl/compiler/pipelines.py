"""Every pass pipeline the compiler runs, built in this one place.

A pipeline is ``kdsl opt -p`` text. Kernels go through their backend's declared
``pipeline`` (the standard optimization pipeline unless the backend says
otherwise), then the instrumentation that their resolved options ask for, and,
when a backward pass is wanted, the adjoint pipelines below.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kdsl.passes import CLEANUP_PIPELINE, DEFAULT_PIPELINE

#: The inline pass that keeps calls to functions with custom gradients, so the
#: adjoint pass sees them as calls (their gradients replace their bodies' VJPs).
INLINE_KEEP_CUSTOM_GRAD = "inline{keep_custom_grad=true}"

#: Before the adjoint pass: the standard pipeline with custom-gradient calls kept.
PRE_ADJOINT_PIPELINE = DEFAULT_PIPELINE.replace("inline", INLINE_KEEP_CUSTOM_GRAD, 1)

#: After the adjoint pass: inline the custom gradients, simplify, then drop the tapes
#: the simplified reverse sweep never reads, and simplify again.
POST_ADJOINT_PIPELINE = f"inline,{CLEANUP_PIPELINE},tape-dce,{CLEANUP_PIPELINE}"


def check_pipeline(options: Mapping[str, Any]) -> str:
    """The passes that instrument a module compiled with (resolved) ``options``.

    ``debug`` inserts a bounds check before every array access, ``verify_fp`` a
    NaN/Inf check before every floating-point store (see docs/debugging.md).
    """
    passes = []
    if options.get("debug"):
        passes.append("bounds-check")
    if options.get("verify_fp"):
        passes.append("fp-check")
    return ",".join(passes)
