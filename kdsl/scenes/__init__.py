"""Simulation scenes written with the public, Warp-compatible API (docs/scenes.md).

A scene is one module here: a kernel factory ``make_kernels(wp, real)`` that uses only
the public API of the ``wp`` it is given (kdsl, or Warp through ``binding.bind``), and
a ``kdsl.scenes.base.Scene`` subclass with its parameters, initial state, right-hand
side, float64 reference and energy. Integrators (``kdsl.scenes.integrators``) are
chosen by name. ``kdsl scene list | run | stability | info`` drive them.

To add a scene: write ``kdsl/scenes/NAME.py`` (copy ``particles.py``), then add its
class to ``SCENES`` below; the CLI and the tests of every scene pick it up.
"""

from __future__ import annotations

import importlib
from typing import Any

from kdsl.scenes.binding import SceneError, bind

#: Scene name -> "module:Class" (imported only when the scene is asked for).
SCENES = {
    "particles": "kdsl.scenes.particles:Particles",
    "chain": "kdsl.scenes.chain:Chain",
    "heat": "kdsl.scenes.heat:Heat",
    "wave": "kdsl.scenes.wave:Wave",
    "stiff_odes": "kdsl.scenes.stiff_odes:StiffOdes",
    "cloth": "kdsl.scenes.cloth:Cloth",
    "nbody": "kdsl.scenes.nbody:NBody",
    "ocean": "kdsl.scenes.ocean:Ocean",
    "throw": "kdsl.scenes.throw:Throw",
}


def scene_names() -> list[str]:
    """The registered scenes' names."""
    return list(SCENES)


def scene_class(name: str) -> Any:
    """The ``Scene`` subclass called ``name`` (a ``SceneError`` listing the names if none)."""
    if name not in SCENES:
        raise SceneError(f"unknown scene {name!r} (choices: {', '.join(SCENES)})")
    module, cls = SCENES[name].split(":")
    return getattr(importlib.import_module(module), cls)


__all__ = ["SCENES", "SceneError", "bind", "scene_class", "scene_names"]
