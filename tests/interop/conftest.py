"""Settings for the interop tests that must be in place before JAX is imported."""

import os

import pytest

# JAX grabs 75% of a GPU's memory per process by default; with one process per
# pytest-xdist worker, that exhausts the GPU. Allocate on demand instead.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")


@pytest.fixture
def jax_on_the_cpu():
    """JAX's default device is the CPU for the test (the modules that use it test the
    CPU paths: on a GPU machine JAX would put new arrays on the GPU)."""
    import jax

    with jax.default_device(jax.devices("cpu")[0]):
        yield
