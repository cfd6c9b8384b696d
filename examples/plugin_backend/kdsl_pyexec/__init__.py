"""kdsl_pyexec: an example kdsl backend plugin that generates Python source.

Registered by its ``pyproject.toml`` as ``pyexec`` in the ``kdsl.backends``
entry-point group; ``BACKEND`` is the instance the entry point names.
"""

from kdsl_pyexec.backend import PyExecBackend

BACKEND = PyExecBackend()

__all__ = ["BACKEND", "PyExecBackend"]
