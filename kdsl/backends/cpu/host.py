"""The compilation target of this host, named without importing llvmlite's binding.

A cached kernel is looked up by a key that names its target (``CpuBackend.load``).
LLVM's own description (host CPU name and feature list) needs ``llvmlite.binding``,
whose import costs about 25 ms, most of a warm start. On Linux the target is named
instead by what determines LLVM's answer:

- the CPU, as the kernel reports it in ``/proc/cpuinfo`` (vendor, family, model and
  feature flags on x86; implementer, part and features on Arm): LLVM derives its CPU
  name and features from the same ``cpuid``/ID registers, so equal fields mean an
  equal target;
- the LLVM build, as llvmlite's version and the size and modification time of its
  shared library (a different LLVM is a different file).

Elsewhere, or when ``/proc/cpuinfo`` says nothing useful, it is LLVM's description
(``jit.target_id``) with llvmlite's and LLVM's versions.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
import sys

#: The ``/proc/cpuinfo`` fields that decide the code LLVM generates for the host (x86,
#: Arm, RISC-V and POWER spellings); per-core and changing fields (MHz, ids) are left out.
_CPU_FIELDS = frozenset(
    {
        "vendor_id", "cpu family", "model", "model name", "stepping", "flags",
        "CPU implementer", "CPU architecture", "CPU variant", "CPU part", "CPU revision",
        "Features", "isa", "uarch", "cpu", "platform",
    }
)  # fmt: skip


def cpuinfo_fields(text: str) -> dict[str, str]:
    """The target-deciding fields of the first processor block of ``/proc/cpuinfo`` text."""
    fields: dict[str, str] = {}
    for line in text.splitlines():
        if not line.strip():
            if fields:
                break  # the end of the first processor's block
            continue
        name, sep, value = line.partition(":")
        name = name.strip()
        if sep and name in _CPU_FIELDS:
            fields[name] = value.strip()
    return fields


def _first_block(path: str = "/proc/cpuinfo") -> str:
    """The first processor's block of ``path`` (a large machine lists hundreds)."""
    lines = []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line.strip() and lines:
                break
            lines.append(line)
    return "".join(lines)


def llvm_build_id() -> str | None:
    """llvmlite's version with its library's size and mtime, read without importing its
    binding (``os.scandir``, and the package's path from ``sys.modules`` once imported:
    ``find_spec`` and a ``pathlib`` glob cost 0.3 ms of a warm compile)."""
    mod = sys.modules.get("llvmlite")
    if mod is not None and getattr(mod, "__path__", None):
        package = next(iter(mod.__path__))
    else:
        spec = importlib.util.find_spec("llvmlite")
        if spec is None or not spec.submodule_search_locations:
            return None
        package = next(iter(spec.submodule_search_locations))
    try:
        with os.scandir(os.path.join(package, "binding")) as entries:
            libs = sorted(e.path for e in entries if "llvmlite" in e.name
                          and e.name.endswith((".so", ".dylib", ".dll")))  # fmt: skip
    except OSError:
        return None
    if not libs:
        return None
    st = os.stat(libs[0])
    import llvmlite  # the package's __init__ only: its version, not the binding

    return f"llvmlite-{llvmlite.__version__}-{st.st_size}-{st.st_mtime_ns}"


@functools.cache
def target_id() -> str:
    """The name of what this host's kernels are compiled for (see the module docstring)."""
    if sys.platform.startswith("linux"):
        try:
            fields = cpuinfo_fields(_first_block())
            build = llvm_build_id()
        except OSError:
            fields, build = {}, None
        if fields and build:
            cpu = hashlib.sha256(repr(sorted(fields.items())).encode()).hexdigest()[:24]
            return f"{os.uname().machine};cpuinfo-{cpu};{build}"
    from kdsl.backends.cpu import jit

    return f"{jit.target_id()};{jit.version_tag()}"
