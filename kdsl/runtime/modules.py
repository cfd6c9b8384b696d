"""Warp's module API: per-module options, ``get_module``, ``load_module``, ``force_load``.

A kernel belongs to the Python module that defines it (``fn.__module__``, Warp's
rule). ``set_module_options({...})``, called in that module or with ``module=``,
sets options for all of its kernels, those defined before the call included; a
kernel's own decorator options win over them. The options that change a kdsl
build (``fast_math``, ``mode``, ``enable_backward``; see ``COMPILE_KEYS``) join each
kernel's compile options, so they key the kernel cache; every other option of
Warp 1.19 is accepted and kept (``get_module_options`` returns it) and has no
effect in kdsl: docs/runtime.md ("Modules and their options") says why, per option.

``load_module``/``force_load`` compile every kernel of a module ahead of time for
each device asked for, so the first launch does no compile work.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Iterable, Mapping
from typing import Any

from kdsl.errors import KdslError, api_boundary
from kdsl.frontend.kernel import Kernel, kernels_of_module, modules_with_kernels
from kdsl.runtime.build_options import ModuleBuildOptions, check_build_options, check_deterministic
from kdsl.runtime.device import Device, get_device, get_devices

#: Warp 1.19's module options and their defaults (``warp.config`` values at import).
DEFAULTS: dict[str, Any] = {
    "max_unroll": 16,
    "enable_backward": True,
    "enable_mathdx_gemm": None,
    "enable_mathdx_solver": None,
    "enable_mathdx_fft": None,
    "fast_math": False,
    "fuse_fp": True,
    "lineinfo": False,
    "cuda_output": None,
    "mode": None,
    "optimization_level": None,
    "cpu_compiler_flags": None,
    "block_dim": 256,
    "compile_time_trace": False,
    "strip_hash": False,
    "extra_build_options": None,
    "deterministic": None,
    "deterministic_max_records": 0,
    "default_grid_stride": None,
}
#: The module options a kdsl build reads; the others are accepted and have no effect.
COMPILE_KEYS = ("enable_backward", "fast_math", "mode")

#: Bumped by every change of any module's options: launch plans compare it (one int).
version = 0


def _check_option(key: str, value: Any) -> None:
    if key not in DEFAULTS:
        known = ", ".join(sorted(DEFAULTS))
        raise KdslError(f"set_module_options: unknown option {key!r} (Warp's options: {known})")
    if key in ("enable_backward", "fast_math", "fuse_fp", "lineinfo", "strip_hash"):
        if not isinstance(value, bool):
            raise KdslError(f"set_module_options: {key!r} must be True or False, not {value!r}")
    elif key == "mode":
        if value not in (None, "release", "debug"):
            raise KdslError(
                f"set_module_options: 'mode' must be 'release', 'debug' or None, not {value!r}"
            )
    elif key in ("max_unroll", "block_dim", "deterministic_max_records"):
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise KdslError(
                f"set_module_options: {key!r} must be a non-negative int, not {value!r}"
            )
    elif key == "extra_build_options":
        check_build_options(value)
    elif key == "deterministic":
        check_deterministic(value)
    elif key == "optimization_level" and value not in (None, 0, 1, 2, 3):
        raise KdslError(
            f"set_module_options: 'optimization_level' must be 0 to 3 or None, not {value!r}"
        )


class Module:
    """The kernels of one Python module and the options they compile with (Warp's ``Module``).

    ``name`` is the Python module's name; ``options`` its option dict (Warp's keys,
    see ``DEFAULTS``); ``kernels`` the kernels defined in it that are alive.
    """

    def __init__(self, name: str | None, loader: Any = None) -> None:
        self.name = name if name is not None else "None"
        self.loader = loader
        self.options: dict[str, Any] = dict(DEFAULTS)
        self._set: dict[str, Any] = {}  # the options set explicitly (they reach compiles)

    @property
    def kernels(self) -> list[Kernel]:
        """The kernels defined in this module (in definition order)."""
        return kernels_of_module(self.name)

    def set_options(self, options: Mapping[str, Any]) -> None:
        """Update options (checked); kernels recompile at their next launch if a build
        option changed."""
        global version
        if not isinstance(options, Mapping):
            raise KdslError(
                f"set_module_options takes a dict of options, not {type(options).__name__}"
            )
        for k, v in options.items():
            _check_option(k, v)
        self.options.update(options)
        self._set.update(options)
        version += 1

    def mark_modified(self) -> None:
        """Make every kernel of the module rebuild its launch plan at its next launch."""
        global version
        version += 1

    def compile_options(self) -> dict[str, Any]:
        """The options set on this module that kdsl builds read (``COMPILE_KEYS``)."""
        out = {k: self._set[k] for k in COMPILE_KEYS if k in self._set}
        if out.get("mode", 0) is None:
            del out["mode"]  # None: kdsl.config.mode decides
        extra = self._set.get("extra_build_options")
        if isinstance(extra, ModuleBuildOptions) and extra.extra_build_dependencies:
            # Warp hashes the dependencies' contents into the module hash: so does the key.
            out["build_dependencies"] = extra.dependency_digest()
        return out

    @api_boundary
    def load(self, device: Any = None, block_dim: int | None = None) -> Module:
        """Compile every kernel of this module for ``device`` (the default device when None).

        A generic kernel (``Any`` parameters) compiles the instances declared with
        ``kdsl.overload``; the others compile per argument types at launch. ``block_dim`` is accepted for Warp's signature; kdsl picks the
        CUDA block size per launch.
        """
        from kdsl.runtime.launch import launch_plan

        dev = get_device(device)
        for k in self.kernels:
            for inst in k.declared_instances() if k.is_generic else [k]:
                launch_plan(inst, dev, None)
        return self

    def unload(self) -> None:
        """Drop every compiled kernel of this module held in this process."""
        for k in self.kernels:
            for inst in [k, *k.instances()]:
                forget_compiled(inst)

    def __repr__(self) -> str:
        return f"<kdsl.Module {self.name!r} ({len(self.kernels)} kernels)>"


_MODULES: dict[str, Module] = {}


def get_module(name: str) -> Module:
    """The ``Module`` of the Python module named ``name`` (created on first use)."""
    if not isinstance(name, str):
        raise KdslError(f"get_module takes a module name (str), not {type(name).__name__}")
    m = _MODULES.get(name)
    if m is None:
        m = _MODULES[name] = Module(name)
    return m


def module_compile_options(name: str | None) -> dict[str, Any]:
    """The build options set on module ``name`` (empty when none were set)."""
    m = _MODULES.get(name) if name is not None else None
    return m.compile_options() if m is not None else {}


def kernel_options(kernel: Any) -> dict[str, Any]:
    """A kernel's effective options: its module's build options, then its own (which win)."""
    own = getattr(kernel, "options", None) or {}
    module = getattr(kernel, "module", None)
    if not _MODULES or module not in _MODULES:
        return dict(own)
    return {**module_compile_options(module), **own}


def backward_enabled(kernel: Any) -> bool:
    """False when the kernel or its module set ``enable_backward=False``."""
    return kernel_options(kernel).get("enable_backward", True) is not False


def forget_compiled(kernel: Any) -> None:
    """Drop what the runtime cached on ``kernel`` (compiled code and launch plans)."""
    from kdsl.runtime.launch import forget

    forget(kernel)


def _caller_module(depth: int) -> str:
    frame = sys._getframe(depth + 1)
    try:
        name = frame.f_globals.get("__name__")
        if not name:
            spec = frame.f_globals.get("__spec__")
            name = spec.name if spec is not None else None
        if not name:
            raise KdslError("cannot tell which module called; pass it explicitly (module=__name__)")
        return name
    finally:
        del frame


def _resolve(module: Any, depth: int) -> Module:
    if isinstance(module, Module):
        return module
    if module is None:
        return get_module(_caller_module(depth + 1))
    if isinstance(module, str):
        return get_module(module)
    if isinstance(module, types.ModuleType):
        return get_module(module.__name__)
    raise KdslError(
        "module must be a kdsl.Module, a Python module or a module name, "
        f"not {type(module).__name__}"
    )


def set_module_options(options: dict[str, Any], module: Any = None) -> None:
    """Set options of the calling module (or of ``module``) for all its kernels.

    Options: Warp's (see ``DEFAULTS``). ``fast_math``, ``mode`` and
    ``enable_backward`` change kdsl builds; the others are accepted and kept.
    """
    _resolve(module, 1).set_options(options)


def get_module_options(module: Any = None) -> dict[str, Any]:
    """The option dict of the calling module (or of ``module``)."""
    return _resolve(module, 1).options


def _devices(device: Any) -> list[Device]:
    if device is None:
        return get_devices()
    if isinstance(device, list | tuple):
        return [get_device(d) for d in device]
    return [get_device(device)]


@api_boundary
def force_load(
    device: Any = None,
    modules: Iterable[Module] | None = None,
    block_dim: int | None = None,
    max_workers: int | None = None,
) -> None:
    """Compile the kernels of ``modules`` (all modules with kernels when None) for
    ``device`` (a device, a list of them, or None for every device).

    ``block_dim`` and ``max_workers`` are accepted for Warp's signature; kdsl
    compiles serially (the backends use every core per compile).
    """
    mods = [get_module(n) for n in modules_with_kernels()] if modules is None else list(modules)
    for m in mods:
        if not isinstance(m, Module):
            raise KdslError(f"force_load: modules must be kdsl.Module objects, not {m!r}")
    for d in _devices(device):
        for m in mods:
            m.load(d, block_dim)


def load_module(
    module: Any = None,
    device: Any = None,
    recursive: bool = False,
    block_dim: int | None = None,
    max_workers: int | None = None,
) -> None:
    """Compile the kernels of ``module`` (the calling module when None) ahead of time.

    ``module`` is a Python module, its name or a ``kdsl.Module``; ``recursive=True``
    adds its submodules. A module without kernels is an error, as in Warp.
    """
    m = _resolve(module, 1)
    mods = [m] if m.kernels else []
    if recursive:
        prefix = m.name + "."
        mods += [get_module(n) for n in modules_with_kernels() if n.startswith(prefix)]
    if not mods:
        raise KdslError(
            f"module '{m.name}' defines no kdsl kernels (or has not been imported yet); "
            "nothing to load"
        )
    force_load(device, mods, block_dim, max_workers)


def clear_kernel_cache() -> None:
    """Empty the kernel cache directory and drop the kernels compiled in this process.

    The next launch of each kernel compiles it again. An unsafe cache directory
    (not the user's, or writable by others) is left alone with an error.
    """
    from kdsl.compiler.cache import MEMORY, DiskCache, cache_dir, check_directory

    directory = cache_dir()
    if directory.exists():
        problem = check_directory(directory, create=False)
        if problem is not None:
            raise KdslError(f"clear_kernel_cache: refusing to clear the kernel cache: {problem}")
        DiskCache(directory).clear()
    MEMORY.clear()
    for name in modules_with_kernels():
        for k in kernels_of_module(name):
            for inst in [k, *k.instances()]:
                forget_compiled(inst)
    config_touch()


def config_touch() -> None:
    """Make every launch plan rebuild (after the compiled kernels were dropped)."""
    global version
    version += 1


__all__ = [
    "Module", "clear_kernel_cache", "force_load", "get_module", "get_module_options",
    "load_module", "set_module_options",
]  # fmt: skip
