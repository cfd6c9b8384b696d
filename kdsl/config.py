"""Process-wide settings, in the style of ``warp.config``: ``kdsl.config.mode = "debug"``.

``mode`` is ``"release"`` (default) or ``"debug"``: debug mode compiles kernels
with a bounds check before every array access. ``verify_fp = True`` adds a check
that no NaN or Inf is stored to memory. A kernel's own options win over these:
``@kdsl.kernel(debug=True)``, ``@kdsl.kernel(mode="release")``,
``@kdsl.kernel(verify_fp=True)``. Settings are read at each launch, and they are
part of the compile options, so debug and release builds are cached apart.

``verify_passes`` says when the pass manager verifies the IR (docs/passes.md):
``"each"`` (after every pass), ``"end"`` (once, after the last pass of a pipeline)
or ``"auto"`` (the default: ``"each"`` in debug mode, ``"end"`` in release). The
environment variable ``KDSL_VERIFY_PASSES`` sets its initial value; the test suite
sets ``"each"``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from kdsl.errors import KdslError

#: "release" or "debug"; see the module docstring.
mode: str = "release"
#: Check that kernels store no NaN or Inf (reported with the source line).
verify_fp: bool = False
#: The most memory (bytes) the backward pass of one launch may take for the tapes of
#: its dynamic loops (see docs/autodiff.md); above it the adjoint launch is refused.
max_tape_bytes: int = 2 * 1024**3
#: The lowest level of message the logger emits (``kdsl.LOG_DEBUG`` 10, ``LOG_INFO`` 20,
#: ``LOG_WARNING`` 30, ``LOG_ERROR`` 40), Warp's ``warp.config.log_level``.
log_level: int = 20
#: Warn when a launch recorded on a tape writes an array that an earlier recorded launch
#: read, which corrupts that launch's gradients (Warp's setting; see
#: ``kdsl/runtime/array_access.py``).
verify_autograd_array_access: bool = False
#: When the pass manager verifies the IR: "auto", "each" or "end" (see above).
verify_passes: str = os.environ.get("KDSL_VERIFY_PASSES") or "auto"

_MODES = ("release", "debug")
_VERIFY_POLICIES = ("auto", "each", "end")
#: Kernel options that ``compile_options`` resolves into ``debug`` / ``verify_fp``.
_DEBUG_KEYS = ("debug", "mode", "verify_fp")


def _check_mode(value: Any, where: str) -> str:
    if value not in _MODES:
        raise KdslError(f"{where} must be 'release' or 'debug', not {value!r}")
    return value


def verify_each_pass() -> bool:
    """Whether the pass manager verifies after every pass (``verify_passes`` resolved).

    Otherwise it verifies once, after the last pass of each pipeline it runs.
    """
    if verify_passes not in _VERIFY_POLICIES:
        raise KdslError(
            "kdsl.config.verify_passes (KDSL_VERIFY_PASSES) must be 'auto', 'each' or "
            f"'end', not {verify_passes!r}"
        )
    if verify_passes == "auto":
        return _check_mode(mode, "kdsl.config.mode") == "debug"
    return verify_passes == "each"


def compile_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """A kernel's options with debug settings resolved against this module's settings.

    The result holds ``debug=True`` and ``verify_fp=True`` only when they are on
    (and never ``mode``), so release builds keep the options they always had.
    """
    out = {k: v for k, v in options.items() if k not in _DEBUG_KEYS}
    debug = options.get("debug")
    if debug is None:
        m = options.get("mode")
        m = (
            _check_mode(m, "kernel option 'mode'")
            if m is not None
            else _check_mode(mode, "kdsl.config.mode")
        )
        debug = m == "debug"
    fp = options.get("verify_fp")
    if fp is None:
        fp = verify_fp
    if debug:
        out["debug"] = True
    if fp:
        out["verify_fp"] = True
    return out


def package_version() -> str:
    """kdsl's version as installed, or ``"source"`` when it runs from a checkout that was
    never installed (``PYTHONPATH`` pointing at the source tree)."""
    from importlib import metadata

    try:
        return metadata.version("kdsl")
    except metadata.PackageNotFoundError:
        return "source"
