"""Public names of the runtime (arrays, devices, launch)."""

__all__: list[str] = []
