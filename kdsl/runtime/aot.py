"""Ahead-of-time modules: Warp's ``compile_aot_module``, ``load_aot_module`` and
``get_cpu_kernel_cache_key``, on kdsl's kernel cache.

``compile_aot_module(module, device, module_dir=d)`` compiles every kernel of the
module for each device and writes each binary (cpu object code, cuda cubin) into
``d`` as a kernel-cache entry (``kdsl.compiler.cache``: atomic, checksummed files
keyed by the optimized IR, backend, options and target). ``load_aot_module(module,
device, module_dir=d)`` -- typically in another process, on a deployment machine --
loads them: the frontend and the IR passes run (milliseconds; the key is a hash of
their output), the backend's compiler (LLVM, NVRTC) never does, and a kernel with no
entry in ``d`` raises ``KernelNotCompiledError`` (a ``FileNotFoundError``, as in
Warp) instead of compiling. After it, launches use the loaded binaries.

Without ``module_dir`` both use the default cache directory. Entries are keyed by
content, so ``strip_hash`` (Warp's option to drop hashes from symbol names) has
nothing to strip and is accepted for the signature.
"""

from __future__ import annotations

import hashlib
import os
import platform
from pathlib import Path
from typing import Any

from kdsl.compiler.cache import KernelNotCompiledError, aot_directory, cache_dir
from kdsl.config import package_version
from kdsl.errors import KdslCapabilityError, KdslTypeError, KdslValueError, api_boundary
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.modules import Module, forget_compiled, get_module


def _module(module: Any, what: str) -> Module:
    if isinstance(module, Module):
        return module
    if isinstance(module, str):
        return get_module(module)
    if hasattr(module, "__name__") and type(module).__name__ == "module":
        return get_module(module.__name__)
    raise KdslTypeError(f"{what}: module must be a kdsl.Module, a Python module or a module "
                        f"name, not {type(module).__name__}")  # fmt: skip


def _devices(device: Any) -> list[Device]:
    if device is None:
        return [get_device(None)]
    if isinstance(device, list | tuple):
        return [get_device(d) for d in device]
    return [get_device(device)]


def _check(devices: list[Device], arch: Any, use_ptx: Any, what: str) -> None:
    if use_ptx:
        raise KdslCapabilityError(f"{what}: use_ptx=True: kdsl's cuda backend stores cubins "
                                  f"for the device's architecture, not PTX")  # fmt: skip
    if arch is None:
        return
    archs = {int(a) for a in (arch if isinstance(arch, list | tuple | set) else [arch])}
    for d in devices:
        if d.is_cpu:
            raise KdslValueError(f"{what}: arch={arch!r} applies to CUDA devices, not '{d}'")
        if archs != {d.arch}:
            raise KdslCapabilityError(f"{what}: arch={arch!r}: kdsl compiles for the "
                                      f"architecture of the device ('{d}' is sm_{d.arch})")  # fmt: skip


def _directory(module_dir: str | os.PathLike | None) -> Path:
    return Path(module_dir) if module_dir is not None else cache_dir()


@api_boundary
def compile_aot_module(
    module: Any,
    device: Any = None,
    arch: int | Any = None,
    module_dir: str | os.PathLike | None = None,
    use_ptx: bool | None = None,
    strip_hash: bool | None = None,
) -> list[Path]:
    """Compile every kernel of ``module`` for ``device`` (one, a list, None: the default
    device) into ``module_dir`` (the kernel cache by default); returns the entries' paths.
    """
    m = _module(module, "compile_aot_module")
    devices = _devices(device)
    _check(devices, arch, use_ptx, "compile_aot_module")
    directory = _directory(module_dir)
    before = set(directory.glob("*.kobj")) if directory.exists() else set()
    with aot_directory(directory, build=True):
        for d in devices:
            for k in m.kernels:
                for inst in [k, *k.instances()]:
                    forget_compiled(inst)  # look every kernel up again: writes its entry
            m.load(d)
    after = set(directory.glob("*.kobj"))
    return sorted(after - before) or sorted(after)


@api_boundary
def load_aot_module(
    module: Any,
    device: Any = None,
    arch: int | None = None,
    module_dir: str | os.PathLike | None = None,
    use_ptx: bool | None = None,
    strip_hash: bool | None = None,
) -> None:
    """Load the kernels of ``module`` that ``compile_aot_module`` wrote to ``module_dir``,
    without compiling any; a missing one raises ``KernelNotCompiledError``."""
    m = _module(module, "load_aot_module")
    devices = _devices(device)
    _check(devices, arch, use_ptx, "load_aot_module")
    directory = _directory(module_dir)
    if not directory.is_dir():
        raise KdslValueError(f"load_aot_module: {directory} is not a directory")
    with aot_directory(directory, build=False):
        for d in devices:
            try:
                m.load(d)
            except KernelNotCompiledError as e:
                raise e.add_context(f"loading module '{m.name}' for '{d}'") from None


def get_cpu_kernel_cache_key(*, cpu_compiler_flags: str | None = None) -> str:
    """A string naming the cpu compilation target, for naming kernel caches built elsewhere:
    kdsl's version, the OS, the machine and a hash of the cpu backend's code version and
    the host CPU (name and features) it compiles for. kdsl always compiles for the host
    CPU, so ``cpu_compiler_flags`` may be None or ``"-march=native"`` (the same target)."""
    if cpu_compiler_flags not in (None, "-march=native"):
        raise KdslCapabilityError(
            f"get_cpu_kernel_cache_key: cpu_compiler_flags={cpu_compiler_flags!r}: kdsl's cpu "
            f"backend JIT-compiles for the host CPU only (None or '-march=native')"
        )
    from kdsl.backends.cpu import host
    from kdsl.backends.registry import get_backend

    cpu = get_backend("cpu")
    target = cpu.cache_target(host.target_id())
    digest = hashlib.sha256(f"{cpu.code_version()}\0{target}".encode()).hexdigest()[:8]
    return f"{package_version()}-{platform.system()}-{platform.machine()}-{digest}"
