"""kdsl standard library: noise (see kdsl/stdlib/__init__.py)."""

__all__: list[str] = []
