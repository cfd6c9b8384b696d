"""``expect_error``: compile a kernel, check the exception, its message and its line."""

from __future__ import annotations

import inspect

import pytest

MARK = "# <-"


def _marked_line(fn) -> tuple[int, str]:
    lines, start = inspect.getsourcelines(fn)
    hits = [(start + k, line) for k, line in enumerate(lines) if MARK in line]
    assert len(hits) == 1, f"{fn.__name__} needs exactly one {MARK!r} marker"
    line, text = hits[0]
    return line, text.split(MARK)[0].strip()


def expect_error(kernel, cls, fragment: str, where=None):
    """Build ``kernel``; assert it raises ``cls`` with ``fragment`` at the marked line.

    ``where`` is the Python function holding the marker (the kernel's by default).
    """
    fn = where if where is not None else kernel.func
    fn = fn.overloads[0].fn if hasattr(fn, "overloads") else fn
    line, text = _marked_line(fn)
    with pytest.raises(cls) as info:
        kernel.build_module()
    err = info.value
    assert fragment in err.message, err.message
    assert err.loc is not None and err.loc.line == line, (err.loc, line, str(err))
    assert text in str(err), str(err)
    assert "^" in str(err)
    # The compiler's own frames are trimmed from the traceback.
    assert not any("emitter.py" in str(e.path) for e in info.traceback)
    return err


@pytest.fixture(name="expect_error")
def expect_error_fixture():
    """The ``expect_error`` helper as a fixture."""
    return expect_error
