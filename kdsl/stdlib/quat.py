"""kdsl standard library: quat (see kdsl/stdlib/__init__.py)."""

__all__: list[str] = []
