"""A pytest plugin that finds tests leaving another CUDA device current.

Run on a machine with several GPUs::

    PYTHONPATH=tools python -m pytest -p pytest_cuda_device_leaks -n 16 -k cuda tests

Each worker appends to ``$OUT/device_leaks_<pid>.txt`` (``/tmp`` without ``$OUT``): a
``LEFT d after TEST`` line for every test after which CUDA's current device is not 0,
and the Python stack of every ``cupy.cuda.runtime.setDevice(n)`` call with ``n != 0``.
With ``KDSL_DEVICE_LEAKS_RESET=1`` it makes device 0 current again after such a test,
which shows how many failures the leak causes. Calls made inside CuPy's compiled code
(``Device.use()``) are not seen; a ``LEFT`` line without a stack points there.
"""

from __future__ import annotations

import os
import traceback

_test = {"id": ""}


def _log(text: str) -> None:
    path = os.path.join(os.environ.get("OUT", "/tmp"), f"device_leaks_{os.getpid()}.txt")
    with open(path, "a") as f:
        f.write(text)


def pytest_configure(config) -> None:
    """Wrap ``setDevice`` to record who switches to a device other than 0."""
    try:
        import cupy
    except ImportError:
        return
    runtime = cupy.cuda.runtime
    original = runtime.setDevice

    def set_device(n: int) -> None:
        if n != 0:
            stack = "".join(traceback.format_stack(limit=9)[:-1])
            _log(f"=== setDevice({n}) in {_test['id']}\n{stack}")
        original(n)

    runtime.setDevice = set_device


def pytest_runtest_logstart(nodeid: str, location: object) -> None:
    """Remember the running test's id for the stacks."""
    _test["id"] = nodeid


def pytest_runtest_logfinish(nodeid: str, location: object) -> None:
    """Record (and optionally undo) a test that left another device current."""
    try:
        import cupy
    except ImportError:
        return
    current = cupy.cuda.runtime.getDevice()
    if current != 0:
        _log(f"=== LEFT {current} after {nodeid}\n")
        if os.environ.get("KDSL_DEVICE_LEAKS_RESET") == "1":
            cupy.cuda.runtime.setDevice(0)
