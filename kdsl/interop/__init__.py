"""Zero-copy exchange of arrays with NumPy, DLPack, PyTorch, JAX, Paddle and CuPy.

The public functions live in ``kdsl.interop.api`` (star-imported by ``kdsl``).
This package imports no framework at import time: torch, jax and paddle are
imported inside the functions that need them, so ``import kdsl`` stays light.
The runtime, one layer below, reaches this package only through the adapters that
``kdsl.interop.api`` registers (``kdsl.runtime.adapters``).
"""
