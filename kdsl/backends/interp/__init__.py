"""The ``interp`` reference backend (registered as ``interp`` by entry point)."""

from kdsl.backends.interp.backend import InterpBackend

#: The instance the ``kdsl.backends`` entry point names.
BACKEND = InterpBackend()

__all__ = ["BACKEND", "InterpBackend"]
