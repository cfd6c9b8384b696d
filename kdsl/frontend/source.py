"""Getting a Python function's source as an AST, with locations in its real file."""

from __future__ import annotations

import ast
import contextlib
import inspect
import textwrap
from collections.abc import Callable
from typing import Any

from kdsl.errors import KdslSyntaxError
from kdsl.ir import Loc


class ParsedSource:
    """A function's ``ast.FunctionDef`` and the map from AST positions to file positions."""

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.fn = fn
        self.name = fn.__name__
        self.file = inspect.getsourcefile(fn) or fn.__code__.co_filename
        try:
            lines, first = inspect.getsourcelines(fn)
        except (OSError, TypeError) as e:
            raise KdslSyntaxError(
                f"cannot read the source of {self.name!r} ({e}); kernels and functions "
                "must be defined in a file"
            ) from None
        text = "".join(lines)
        #: The function's source text as written (the kernel cache's source index digests it).
        self.text = text
        self.indent = len(lines[0]) - len(lines[0].lstrip())
        self.line_offset = first - 1
        tree = ast.parse(textwrap.dedent(text))
        defs = [n for n in tree.body if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
        if not defs:
            raise KdslSyntaxError(f"{self.name!r} is not a plain function definition")
        self.tree: ast.FunctionDef = defs[0]  # type: ignore[assignment]

    def loc(self, node: ast.AST | None) -> Loc:
        """The file location of ``node`` (the function's line when None)."""
        node = node if node is not None and hasattr(node, "lineno") else self.tree
        end_line = getattr(node, "end_lineno", None)
        end_col = getattr(node, "end_col_offset", None)
        return Loc(
            self.file,
            node.lineno + self.line_offset,
            node.col_offset + self.indent + 1,
            end_line + self.line_offset if end_line is not None else None,
            end_col + self.indent + 1 if end_col is not None else None,
        )

    def closure_vars(self) -> dict[str, Any]:
        """The function's closure cells, by name (empty cells left out)."""
        code = self.fn.__code__
        out: dict[str, Any] = {}
        for name, cell in zip(code.co_freevars, self.fn.__closure__ or ()):
            with contextlib.suppress(ValueError):  # an empty cell
                out[name] = cell.cell_contents
        return out
