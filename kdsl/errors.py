"""The kdsl exception hierarchy and the rendering of source locations.

Every user mistake raises a ``KdslError`` subclass carrying a ``Loc``. Its message
names the file, line and column, shows the source line with carets under the
span, and says what was expected and what was found::

    kdsl.errors.KdslTypeError: cannot add f32 and f64: operands must have the same type
      File "sim.py", line 12, column 9, in integrate:
        v1 = v0 + dt * 2.0
             ^^^^^^^^^^^^^
"""

from __future__ import annotations

import functools
import linecache
import os
import traceback
import types
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from kdsl.ir.core import Loc


class KdslError(Exception):
    """Base class of every error kdsl raises for a user mistake."""

    def __init__(self, message: str, loc: Loc | None = None, func: str | None = None) -> None:
        self.message = message
        self.loc = loc
        self.func = func
        self.context: list[str] = []
        super().__init__(message)

    def add_context(self, note: str) -> KdslError:
        """Record where the error passed through ("during pass fold", ...)."""
        self.context.append(note)
        return self

    def __str__(self) -> str:
        text = self.message
        if self.loc is not None and self.loc.line > 0:
            text += "\n" + render_loc(self.loc, self.func)
        for note in self.context:
            text += f"\n  ({note})"
        return text


class KdslSyntaxError(KdslError):
    """Python the kernel language does not accept (lambda, try, a list, ...)."""


class KdslTypeError(KdslError):
    """Operands, arguments or assignments whose types do not fit."""


class KdslNameError(KdslError):
    """An undefined name, or a variable that may be unassigned where it is read."""


class KdslVerifyError(KdslError):
    """IR that breaks an invariant (raised by the verifier and the parser)."""


class KdslCapabilityError(KdslError):
    """A kernel needs something the chosen backend does not support."""


class KdslLaunchError(KdslError):
    """Bad arguments to ``kdsl.launch`` (count, dtype, ndim, device).

    ``loc`` is the user's ``launch`` call; ``kernel_loc`` (when known) the ``def`` line
    of the kernel launched, rendered after it.
    """

    kernel_loc: Loc | None = None
    kernel_name: str | None = None

    def __str__(self) -> str:
        text = super().__str__()
        if self.kernel_loc is not None:
            text += f"\n  kernel '{self.kernel_name}' is defined at:\n" + render_loc(
                self.kernel_loc, self.kernel_name
            )
        return text


class KdslRuntimeError(KdslError):
    """A failure while a kernel ran (out-of-bounds access in debug mode, ...)."""


class KdslAttributeError(KdslTypeError, AttributeError):
    """An attribute a value in a kernel does not have (``v.w`` on a vec3, an unknown field)."""


class KdslIndexError(KdslTypeError, IndexError):
    """A constant index out of range in a kernel (a tuple's, a vector's)."""


class KdslKeyError(KdslError, KeyError):
    """A name looked up in a table that lacks it (an unknown option, stage or backend)."""

    def __str__(self) -> str:  # KeyError's own __str__ would print the message's repr
        return KdslError.__str__(self)


class KdslValueError(KdslError, ValueError):
    """An argument of the right type but a wrong value (a negative size, an unknown mode)."""


class KdslDeterminismError(KdslError, RuntimeError):
    """A determinism mode kdsl cannot provide for a kernel (Warp's ``WarpDeterminismError``)."""


# Warp's names for its compile errors: a Warp program's ``except wp.WarpCodegenError``
# catches kdsl's (every kdsl error, as Warp raises that class for every codegen failure).
WarpCodegenError = KdslError
WarpCodegenTypeError = KdslTypeError
WarpCodegenAttributeError = KdslAttributeError
WarpCodegenIndexError = KdslIndexError
WarpCodegenKeyError = KdslKeyError
WarpCodegenValueError = KdslValueError
WarpDeterminismError = KdslDeterminismError


class KdslGradientWarning(UserWarning):
    """A differentiable kernel whose gradient may be wrong (e.g. it reads an array it wrote)."""


def source_line(file: str, line: int) -> str | None:
    """The text of ``line`` in ``file``, or None when it cannot be read."""
    text = linecache.getline(file, line)
    return text.rstrip("\n") if text else None


def render_loc(loc: Loc, func: str | None = None) -> str:
    """The ``File ..., line ...`` header, the source line and carets under the span;
    for code inlined from a function, each call it came through after it ("called
    from", out to the kernel's line)."""
    text = _render_one(loc, func)
    caller = getattr(loc, "caller", None)
    while caller is not None:
        text += "\n" + _render_one(caller, None, "called from")
        caller = getattr(caller, "caller", None)
    return text


def _render_one(loc: Loc, func: str | None, lead: str = "") -> str:
    where = f'  {lead} File "{loc.file}"' if lead else f'  File "{loc.file}"'
    where += f", line {loc.line}, column {loc.col}"
    if func:
        where += f", in {func}"
    where += ":"
    text = source_line(loc.file, loc.line)
    if text is None:
        return where
    stripped = text.lstrip()
    indent = len(text) - len(stripped)
    start = max(loc.col - 1 - indent, 0)
    if loc.end_line == loc.line and loc.end_col is not None and loc.end_col > loc.col:
        width = loc.end_col - loc.col
    else:
        width = max(len(stripped) - start, 1)
    return f"{where}\n    {stripped}\n    {' ' * start}{'^' * width}"


def full_tracebacks() -> bool:
    """True when ``KDSL_TRACEBACK=full`` asks for kdsl-internal frames.

    Read at each error, so setting ``os.environ["KDSL_TRACEBACK"] = "full"`` in a
    running program (a notebook) takes effect at the next error.
    """
    return os.environ.get("KDSL_TRACEBACK", "").lower() == "full"


# --- short tracebacks ------------------------------------------------------------
# A kdsl error raised from a user call (launch, Tape.backward, a module load) carries
# the frames of every kdsl function it passed through: five to ten frames of launch
# plans, the compile driver and the frontend before the one message that matters,
# which already names the user's file and line. As JAX does
# (jax/_src/traceback_util.py), the public entry points are API boundaries: a
# KdslError leaving one keeps only the frames outside the kdsl package (the user's),
# and says so in a note. KDSL_TRACEBACK=full keeps everything.

#: The kdsl package directory: frames of files under it are kdsl-internal.
_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__)) + os.sep
#: The note added to a filtered error (once).
HIDDEN_FRAMES_NOTE = "(kdsl-internal frames hidden; set KDSL_TRACEBACK=full to show them)"

F = TypeVar("F", bound=Callable[..., Any])


def is_internal_frame(filename: str) -> bool:
    """True for a frame of kdsl's own code (a file under the kdsl package)."""
    return os.path.abspath(filename).startswith(_PACKAGE_DIR)


def filter_traceback(tb: types.TracebackType | None) -> types.TracebackType | None:
    """``tb`` without kdsl-internal frames (the user's frames, in order)."""
    out = None
    for frame, lineno in reversed(list(traceback.walk_tb(tb))):
        if not is_internal_frame(frame.f_code.co_filename):
            out = types.TracebackType(out, frame, frame.f_lasti, lineno)
    return out


def hide_internal_frames(err: KdslError) -> KdslError:
    """Drop kdsl-internal frames from ``err``'s traceback and add a note saying so,
    unless ``KDSL_TRACEBACK=full``; re-raise it with a bare ``raise`` (which adds no
    frame). Idempotent: nested boundaries filter again and note once."""
    if not full_tracebacks():
        err.with_traceback(filter_traceback(err.__traceback__))
        if HIDDEN_FRAMES_NOTE not in getattr(err, "__notes__", ()):
            err.add_note(HIDDEN_FRAMES_NOTE)
    return err


def api_boundary(fn: F) -> F:
    """Make ``fn`` (a public entry point) drop kdsl-internal frames from the traceback
    of a ``KdslError`` leaving it, unless ``KDSL_TRACEBACK=full``.

    Boundaries nest: an inner one filters what is below it, the outer one the rest.
    Only ``KdslError`` is filtered; any other exception (a kdsl bug, or the user's own
    error inside a callback) keeps its full traceback. It costs a call; on the hottest
    paths (``launch``) call ``hide_internal_frames`` in an ``except`` instead.
    """

    @functools.wraps(fn)
    def boundary(*args: Any, **kwargs: Any) -> Any:
        __tracebackhide__ = True  # pytest and IPython hide this frame too
        try:
            return fn(*args, **kwargs)
        except KdslError as e:
            hide_internal_frames(e)
            raise

    return boundary  # type: ignore[return-value]
