"""Renderers with Warp's ``warp.render`` API (docs/render.md).

``import kdsl.render`` (as ``import warp.render``) gives ``kdsl.render.UsdRenderer``,
which writes an animated USD stage through usd-core (the ``usd`` extra), and
``kdsl.render.OpenGLRenderer``, which exists for Warp programs but refuses to open a
window (kdsl has no OpenGL viewer) and names the alternatives.
"""

from __future__ import annotations

from kdsl.render.inputs import RenderDependencyError
from kdsl.render.opengl import OpenGLRenderer
from kdsl.render.usd import UsdRenderer

__all__ = ["OpenGLRenderer", "RenderDependencyError", "UsdRenderer"]
