"""``kdsl.launch``: check arguments, pick a backend, compile once, run.

The kernel object (from the frontend) offers ``.key`` (its function symbol),
``.name``, ``.arg_names``, ``.arg_types`` (IR types), ``.tid_ndim`` and
``.build_module()``. Compiled kernels are cached on the kernel object, one per
backend (and backend version and options).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from kdsl import config
from kdsl.backends.base import Backend, CompiledKernel
from kdsl.backends.registry import get_backend, is_registered
from kdsl.errors import KdslError, KdslLaunchError
from kdsl.runtime.args import ArgError, convert, launch_error
from kdsl.runtime.device import Device, get_device

_CACHE_ATTR = "_kdsl_compiled"


def default_backend_for(device: Any) -> str:
    """The backend name used for ``device`` when ``launch`` names none."""
    dev = get_device(device)
    if dev.is_cpu:
        return "cpu" if is_registered("cpu") else "interp"
    return dev.kind


def _resolve_backend(backend: Any, device: Device) -> Backend:
    if isinstance(backend, Backend):
        b = backend
    else:
        name = backend or default_backend_for(device)
        try:
            b = get_backend(name)
        except KdslError:
            if backend is None and name == "cpu":  # a broken cpu plugin: fall back
                b = get_backend("interp")
            else:
                raise
    if not b.serves(device.alias):
        raise KdslLaunchError(
            f"backend '{b.name}' cannot run on device '{device}' (it serves {b.devices()})"
        )
    return b


def normalize_dim(dim: Any, kernel_name: str = "?") -> tuple[int, ...]:
    """The launch grid as a tuple of 1 to 4 non-negative ints."""
    if isinstance(dim, int | np.integer) and not isinstance(dim, bool):
        dims: tuple = (int(dim),)
    elif isinstance(dim, Sequence) and all(
        isinstance(d, int | np.integer) and not isinstance(d, bool) for d in dim
    ):
        dims = tuple(int(d) for d in dim)
    else:
        raise KdslLaunchError(
            f"kernel '{kernel_name}': dim must be an int or a tuple of ints, got {dim!r}"
        )
    if not 1 <= len(dims) <= 4 or any(d < 0 for d in dims):
        raise KdslLaunchError(
            f"kernel '{kernel_name}': dim must have 1 to 4 non-negative entries, got {dim!r}"
        )
    return dims


def _kernel_name(kernel: Any) -> str:
    return getattr(kernel, "name", None) or getattr(kernel, "key", "?")


def _check_tid(kernel: Any, dims: tuple[int, ...]) -> None:
    nd = getattr(kernel, "tid_ndim", 0) or 0
    if nd > 1 and nd != len(dims):
        raise KdslLaunchError(
            f"kernel '{_kernel_name(kernel)}' uses a {nd}-d thread index "
            f"({', '.join('ijkl'[:nd])} = tid()) but was launched with {len(dims)}-d "
            f"dim={dims if len(dims) > 1 else dims[0]}"
        )


def _compiled(kernel: Any, backend: Backend) -> CompiledKernel:
    cache = getattr(kernel, _CACHE_ATTR, None)
    if cache is None:
        cache = {}
        setattr(kernel, _CACHE_ATTR, cache)
    # Process-wide debug settings (kdsl.config) resolve into the options, so they key the cache.
    options = config.compile_options(getattr(kernel, "options", None) or {})
    key = (backend.name, backend.version, repr(sorted(options.items())))
    compiled = cache.get(key)
    if compiled is None:
        compiled = backend.compile(kernel.build_module(), kernel.key, options)
        compiled.metadata.setdefault("name", _kernel_name(kernel))
        cache[key] = compiled
    return compiled


class Launch:
    """A recorded launch (``record_cmd=True``) that relaunches with little Python work."""

    def __init__(
        self,
        kernel: Any,
        backend: Backend,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: list,
        device: Device,
        stream: Any,
    ) -> None:
        self.kernel = kernel
        self.backend = backend
        self.compiled = compiled
        self.dims = dims
        self.params = args
        self.device = device
        self.stream = stream

    def set_param_at_index(self, index: int, value: Any) -> None:
        """Replace argument ``index`` (checked like ``launch`` checks it)."""
        names, types = self.kernel.arg_names, self.kernel.arg_types
        if not 0 <= index < len(types):
            raise KdslLaunchError(
                f"kernel '{_kernel_name(self.kernel)}' has {len(types)} parameters; "
                f"there is no index {index}"
            )
        self.params[index] = _convert_one(
            self.kernel, index, names[index], types[index], value, self.device
        )

    def set_param_by_name(self, name: str, value: Any) -> None:
        """Replace the argument of parameter ``name``."""
        names = list(self.kernel.arg_names)
        if name not in names:
            raise KdslLaunchError(f"kernel '{_kernel_name(self.kernel)}' has no parameter '{name}'")
        self.set_param_at_index(names.index(name), value)

    def set_dim(self, dim: Any) -> None:
        """Change the launch grid."""
        dims = normalize_dim(dim, _kernel_name(self.kernel))
        _check_tid(self.kernel, dims)
        self.dims = dims

    def launch(self, stream: Any = None) -> None:
        """Run the recorded launch."""
        self.backend.launch(
            self.compiled, self.dims, self.params, stream if stream is not None else self.stream
        )


def _convert_one(kernel: Any, index: int, name: str, t: Any, value: Any, device: Device) -> Any:
    try:
        return convert(t, value, device)
    except ArgError as e:
        raise launch_error(_kernel_name(kernel), index, name, str(e)) from None


def launch(
    kernel: Any,
    dim: Any,
    inputs: Sequence[Any] = (),
    outputs: Sequence[Any] = (),
    adj_inputs: Sequence[Any] = (),
    adj_outputs: Sequence[Any] = (),
    device: Any = None,
    stream: Any = None,
    adjoint: bool = False,
    record_cmd: bool = False,
    max_blocks: int = 0,
    block_dim: int = 256,
    backend: Any = None,
) -> Launch | None:
    """Run ``kernel`` once per index of ``dim`` with ``inputs`` then ``outputs`` as arguments.

    ``dim`` is an int or a tuple of 1 to 4 ints. Arguments are checked against the
    kernel's parameters (count, dtype, ndim, device). With ``record_cmd=True`` the
    launch is not run but returned as a ``Launch`` to run (and rerun) later.
    """
    name = _kernel_name(kernel)
    if adjoint:
        raise KdslError(f"kernel '{name}': adjoint launches are not supported yet")
    dims = normalize_dim(dim, name)
    dev = get_device(device)
    args = [*inputs, *outputs]
    names, types = list(kernel.arg_names), list(kernel.arg_types)
    if len(args) != len(types):
        raise KdslLaunchError(
            f"kernel '{name}' takes {len(types)} arguments ({', '.join(names)}) but "
            f"{len(args)} were given ({len(inputs)} inputs, {len(outputs)} outputs)"
        )
    converted = [
        _convert_one(kernel, i, n, t, v, dev) for i, (n, t, v) in enumerate(zip(names, types, args))
    ]
    _check_tid(kernel, dims)
    b = _resolve_backend(backend, dev)
    cmd = Launch(kernel, b, _compiled(kernel, b), dims, converted, dev, stream)
    if record_cmd:
        return cmd
    cmd.launch()
    return None
