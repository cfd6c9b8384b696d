"""``kdsl.render.OpenGLRenderer``: named for Warp programs, refused with the alternatives.

kdsl ships no OpenGL viewer (no window, GL context or GUI toolkit). Warp's examples
build an ``OpenGLRenderer`` only when they are not headless, so the class exists with
Warp's constructor signature and raises a ``KdslCapabilityError`` that names what kdsl
offers instead: ``kdsl.render.UsdRenderer`` (the same drawing calls, written to a USD
file) and ``kdsl scene run NAME --render out.gif`` for pictures of kdsl's scenes.
"""

from __future__ import annotations

from typing import Any

from kdsl.errors import KdslCapabilityError
from kdsl.render.inputs import user_loc

MESSAGE = (
    "kdsl.render.OpenGLRenderer: kdsl has no OpenGL viewer (no window or GUI toolkit). "
    "Run the program headless (Warp's examples take --headless), write the frames with "
    "kdsl.render.UsdRenderer(path) instead (the same render_* calls, to a USD file; "
    "pip install 'kdsl[usd]'), or draw a kdsl scene with `kdsl scene run NAME --render "
    "out.gif` (docs/render.md)"
)


class OpenGLRenderer:
    """Warp's interactive OpenGL renderer: not available in kdsl (construction raises).

    Takes Warp's constructor arguments so that the error is this one, not a
    ``TypeError``; see the module docstring for the alternatives.
    """

    def __init__(
        self,
        title: str = "Warp",
        scaling: float = 1.0,
        fps: int = 60,
        up_axis: str = "Y",
        screen_width: int = 1024,
        screen_height: int = 768,
        *args: Any,
        **kwargs: Any,
    ) -> None:
        raise KdslCapabilityError(MESSAGE, user_loc())
