"""kdsl standard library: linalg (see kdsl/stdlib/__init__.py)."""

__all__: list[str] = []
