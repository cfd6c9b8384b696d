"""The ``wp`` module a scene's kernels are written against: kdsl, or Warp itself.

A scene file never imports ``kdsl`` or ``warp`` for its kernels. Its kernel factory
takes the module as an argument (``make_kernels(wp, real)``), and the scene object
gets it from ``bind(name)``. So the same file runs under kdsl (``bind("kdsl")``,
the default) and under NVIDIA Warp (``bind("warp")``), which the benchmark and
``tests/scenes/test_warp_binding.py`` use.
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any, NamedTuple

from kdsl.errors import KdslError

#: The frameworks a scene can be bound to.
BINDINGS = ("kdsl", "warp")


class SceneError(KdslError):
    """A bad scene request (unknown name, integrator or precision, bad dt, no backend)."""


def bind(name: str = "kdsl") -> ModuleType:
    """The ``wp`` module called ``name`` ("kdsl" or "warp"), initialized."""
    if name not in BINDINGS:
        raise SceneError(f"unknown binding {name!r} (choices: {', '.join(BINDINGS)})")
    try:
        wp = importlib.import_module(name)
    except ImportError as e:
        raise SceneError(f"cannot bind scenes to {name}: {e} (pip install warp-lang)") from None
    if name == "warp":
        wp.config.quiet = True  # no "Module ... load took" lines between our outputs
        wp.init()
    return wp


def is_kdsl(wp: ModuleType) -> bool:
    """True when ``wp`` is kdsl (kdsl-only extras, such as ``backend=``, apply)."""
    return wp.__name__ == "kdsl"


class KernelTypes(NamedTuple):
    """The types scene kernels annotate with, for one ``wp`` and float type ``real``."""

    vec3: Any
    Vec3Array: Any
    RealArray: Any
    IntArray: Any


def kernel_types(wp: ModuleType, real: Any) -> KernelTypes:
    """``vec3`` of ``real`` and the arrays of ``vec3``, ``real`` and ``int`` under ``wp``:
    named once, so that kernel signatures stay short (``x: Vec3Array``)."""
    vec3 = wp.types.vector(3, real)
    return KernelTypes(vec3, wp.array(dtype=vec3), wp.array(dtype=real), wp.array(dtype=int))
