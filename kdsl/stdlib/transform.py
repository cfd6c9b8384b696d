"""kdsl standard library: transform (see kdsl/stdlib/__init__.py)."""

__all__: list[str] = []
