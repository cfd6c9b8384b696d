"""Settings for the interop tests that must be in place before JAX is imported."""

import os

# JAX grabs 75% of a GPU's memory per process by default; with one process per
# pytest-xdist worker, that exhausts the GPU. Allocate on demand instead.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
