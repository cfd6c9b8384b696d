"""kdsl's standard library: kernel-language functions written in kdsl itself.

Everything a backend need not lower as a primitive (quaternion and transform
algebra, spatial algebra, matrix decompositions, random numbers, noise) is
``@kdsl.func`` code here, compiled by every backend like user code and only when
a kernel calls it. ``kdsl.stdlib.api`` gathers the public names.

docs/builtins.md lists each public function under its module's ``__kdsl_group__``,
or under the group ``doc_group`` gives it.
"""

from collections.abc import Callable
from typing import Any


def doc_group(name: str) -> Callable[[Any], Any]:
    """Decorator (above ``@kdsl.func``): list the function under group ``name`` in
    docs/builtins.md instead of its module's ``__kdsl_group__``."""

    def deco(fn: Any) -> Any:
        fn.__kdsl_group__ = name
        return fn

    return deco
