"""Public names of the frontend (decorators, kernel-language builtins)."""

__all__: list[str] = []
