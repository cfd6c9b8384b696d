"""Kernels compiled from a source file a test writes, so that a compile error can name
the file, the line and the source line (``exec`` of a string names no file)."""

from __future__ import annotations

import textwrap
import types
from pathlib import Path
from typing import Any


def kernel_from_file(directory: Path, params: str, body: str, module: str = "bad_kernel"
                     ) -> tuple[Any, Path]:  # fmt: skip
    """The kernel ``bad(<params>)`` whose body is the one line ``body``, written to
    ``directory/<module>.py`` and compiled from there (line 5 is the body), and the
    file's path."""
    src = textwrap.dedent(f"""\
        import kdsl as wp

        @wp.kernel
        def bad({params}):
            {body}
        """)  # fmt: skip
    path = directory / f"{module}.py"
    path.write_text(src)
    mod = types.ModuleType(module)
    exec(compile(src, str(path), "exec"), mod.__dict__)
    return mod.bad, path
