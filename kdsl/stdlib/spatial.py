"""kdsl standard library: spatial (see kdsl/stdlib/__init__.py)."""

__all__: list[str] = []
