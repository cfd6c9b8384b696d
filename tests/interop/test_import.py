"""``import kdsl`` must not import any framework; the interop names are public."""

import subprocess
import sys

import kdsl as wp

NAMES = [
    "from_numpy", "dtype_to_numpy", "dtype_from_numpy", "from_torch", "to_torch",
    "device_from_torch", "device_to_torch", "dtype_from_torch", "dtype_to_torch",
    "stream_from_torch", "stream_to_torch", "from_jax", "to_jax", "device_from_jax",
    "device_to_jax", "dtype_from_jax", "dtype_to_jax", "from_dlpack", "to_dlpack",
    "from_paddle", "to_paddle", "device_from_paddle", "device_to_paddle",
    "dtype_from_paddle", "dtype_to_paddle", "stream_from_paddle", "ArrayDescriptor",
]  # fmt: skip


def test_import_kdsl_imports_no_framework():
    code = (
        "import sys, kdsl\n"
        "kdsl.from_torch, kdsl.to_jax, kdsl.from_paddle\n"
        "bad = [m for m in ('torch', 'jax', 'jaxlib', 'paddle', 'cupy') if m in sys.modules]\n"
        "print(bad)\n"
        "sys.exit(1 if bad else 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_public_names():
    for name in NAMES:
        assert callable(getattr(wp, name)), name
