"""kdsl standard library: random (see kdsl/stdlib/__init__.py)."""

__all__: list[str] = []
