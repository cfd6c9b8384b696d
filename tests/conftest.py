"""Repository-wide test settings.

Tests use a private kernel cache directory, and the pass manager verifies the IR after
every pass, as in debug mode (release builds verify once per pipeline; see
docs/passes.md): ``KDSL_VERIFY_PASSES=each`` for the CLI's subprocesses and
``kdsl.config.verify_passes`` for this process. Under CI (``CI`` set) Hypothesis runs
derandomized, so a landing is decided by the code and not by the luck of a random
search; locally it searches freshly each run.
"""

import os
import tempfile

from hypothesis import settings

# Kernels compiled by the tests never touch the user's real kernel cache.
os.environ.setdefault("KDSL_CACHE_DIR", tempfile.mkdtemp(prefix="kdsl-test-cache-"))

# Every test verifies the IR after every pass, whatever the environment says.
os.environ["KDSL_VERIFY_PASSES"] = "each"
import kdsl.config  # reads the environment above

kdsl.config.verify_passes = "each"

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def pytest_collection_finish(session) -> None:
    """Make CUDA device 0 current again once the test modules are imported.

    Collecting the JAX interop tests initializes JAX, whose client leaves the last GPU
    current; tests that make CuPy arrays with CuPy's defaults expect device 0. kdsl's own
    work must not depend on it: tests/runtime/test_other_device_current.py checks that.
    """
    import kdsl

    if kdsl.get_cuda_device_count() > 1:
        import cupy

        cupy.cuda.runtime.setDevice(0)
