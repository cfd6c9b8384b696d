"""Checking where a kernel's compile error points: at the line its source marks ``# <-``."""

import inspect

import pytest

from kdsl.errors import KdslTypeError


def expect_error_at_marker(kernel, fragment: str, caret: bool = True) -> None:
    """Building ``kernel`` raises a KdslTypeError whose message holds ``fragment``, located
    at the line marked ``# <-``; with ``caret``, the message underlines the source."""
    lines, start = inspect.getsourcelines(kernel.func)
    line = next(start + k for k, text in enumerate(lines) if "# <-" in text)
    with pytest.raises(KdslTypeError) as info:
        kernel.build_module()
    assert fragment in info.value.message, info.value.message
    assert info.value.loc is not None and info.value.loc.line == line, str(info.value)
    if caret:
        assert "^" in str(info.value)
