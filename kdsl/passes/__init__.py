"""kdsl's IR passes and the pass manager.

Each pass lives in its own file (``fold.py`` is the ``fold`` pass) and is found by
``get_all_passes()``. ``run_pipeline(module, "inline,fold,cse")`` runs a textual
pipeline through a ``PassManager``; ``optimize(module)`` runs the standard one.
"""

from __future__ import annotations

from typing import Any

from kdsl.ir import Module
from kdsl.passes.manager import (
    ModulePass,
    PassCrashError,
    PassManager,
    PassTiming,
    get_all_passes,
    get_pass,
    parse_pipeline,
    parse_pipeline_spec,
    pass_names,
    pipeline_str,
    run_fixpoint,
)

#: The standard optimization pipeline, as ``kdsl opt -p`` text.
DEFAULT_PIPELINE = "inline,fold,canonicalize,fold,cse,dce"

#: The cleanup rounds ``optimize`` repeats after inlining, until nothing changes.
CLEANUP_PIPELINE = "fold,canonicalize,cse,dce"


def run_pipeline(
    module: Module, pipeline: str = DEFAULT_PIPELINE, **manager_options: Any
) -> Module:
    """Run ``pipeline`` over ``module`` in place (see ``PassManager`` for the options)."""
    PassManager(pipeline, **manager_options).run(module)
    return module


def optimize(module: Module, max_rounds: int = 4, **manager_options: Any) -> Module:
    """Inline, then repeat ``CLEANUP_PIPELINE`` until it changes nothing (bounded)."""
    run_pipeline(module, "inline", **manager_options)
    manager = PassManager(CLEANUP_PIPELINE, **manager_options)
    for _ in range(max_rounds):
        if not manager.run(module):
            break
    return module


__all__ = [
    "CLEANUP_PIPELINE", "DEFAULT_PIPELINE", "ModulePass", "PassCrashError", "PassManager",
    "PassTiming", "get_all_passes", "get_pass", "optimize", "parse_pipeline",
    "parse_pipeline_spec", "pass_names", "pipeline_str", "run_fixpoint", "run_pipeline",
]  # fmt: skip
