"""Zero-copy exchange of arrays with NumPy, DLPack, PyTorch, JAX, Paddle and CuPy.

The public functions live in ``kdsl.interop.api`` (star-imported by ``kdsl``).
This package imports no framework at import time: torch, jax and paddle are
imported inside the functions that need them, so ``import kdsl`` stays light.
Keep this file free of imports: ``kdsl.runtime.args`` imports
``kdsl.interop.descriptor`` while the runtime itself is being imported.
"""
