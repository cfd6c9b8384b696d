"""``kdsl.launch``: check arguments, pick a backend, compile once, run.

The kernel object (from the frontend) offers ``.key`` (its function symbol),
``.name``, ``.arg_names``, ``.arg_types`` (IR types), ``.tid_ndim`` and
``.build_module()``. Compiled kernels are cached on the kernel object, one per
backend (and backend version and options).
"""

from __future__ import annotations

import inspect
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from kdsl import config
from kdsl.backends.base import Backend, CompiledKernel
from kdsl.backends.registry import get_backend, is_registered
from kdsl.compiler import compile_kernel, load_support
from kdsl.errors import KdslError, KdslLaunchError, hide_internal_frames
from kdsl.ir import types as T
from kdsl.ir.core import Loc
from kdsl.runtime import modules as _modules
from kdsl.runtime import tape as _tape
from kdsl.runtime import timing as _timing
from kdsl.runtime.args import ArgError, convert, launch_error
from kdsl.runtime.array import array
from kdsl.runtime.descriptor import ArrayDescriptor
from kdsl.runtime.device import Device, get_device
from kdsl.runtime.graphs import state as _graphs
from kdsl.runtime.launch_reuse import LaunchReuse, by_value_indices
from kdsl.runtime.objects import foreign_id
from kdsl.runtime.stream import current_stream

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
        except KdslError as e:
            if backend is None and name == "cpu":  # a broken cpu plugin: fall back, loudly
                b = get_backend("interp")
                _warn_interp_fallback(e.message)
            elif backend is not None:  # the caller's backend= argument: a launch mistake
                raise KdslLaunchError(f"launch(backend={backend!r}): {e.message}") from None
            else:
                raise
    if not b.serves(device.alias):
        raise KdslLaunchError(
            f"backend '{b.name}' cannot run on device '{device}' (it serves {b.devices()})"
        )
    return b


_warned_fallback = False


def _warn_interp_fallback(reason: str) -> None:
    """Say once per process that cpu launches run on the interpreter, and why: a benchmark
    or a simulation would otherwise just run hundreds of times slower."""
    global _warned_fallback
    if not _warned_fallback:
        _warned_fallback = True
        warnings.warn(
            f"kdsl: launches on 'cpu' run on the interp backend (a reference interpreter, "
            f"hundreds of times slower) because the cpu backend did not load: {reason}",
            RuntimeWarning, stacklevel=4,
        )  # fmt: skip


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


def check_tid(kernel: Any, dims: tuple[int, ...]) -> None:
    """Refuse a grid whose rank differs from the kernel's n-d ``tid()`` (n > 1)."""
    nd = getattr(kernel, "tid_ndim", 0) or 0
    if nd > 1 and nd != len(dims):
        raise KdslLaunchError(
            f"kernel '{_kernel_name(kernel)}' uses a {nd}-d thread index "
            f"({', '.join('ijkl'[:nd])} = tid()) but was launched with {len(dims)}-d "
            f"dim={dims if len(dims) > 1 else dims[0]}"
        )


def _compiled(kernel: Any, backend: Backend, options: dict[str, Any]) -> CompiledKernel:
    cache = getattr(kernel, _CACHE_ATTR, None)
    if cache is None:
        cache = {}
        setattr(kernel, _CACHE_ATTR, cache)
    key = (backend.name, backend.version, repr(sorted(options.items())))
    compiled = cache.get(key)
    if compiled is None:
        compiled = compile_kernel(backend, kernel, options=options)
        compiled.metadata.setdefault("name", _kernel_name(kernel))
        cache[key] = compiled
    return compiled


def resolve_stream(device: Device, stream: Any) -> Any:
    """The stream a launch on ``device`` runs on: the user's, else the device's current one."""
    if stream is not None or device.is_cpu:
        return stream
    return current_stream(device)  # no import statement here: one costs microseconds


class _Plan:
    """What a kernel's launches on one device and backend share (see ``launch_plan``)."""

    __slots__ = (
        "alias", "backend", "backend_arg", "compiled", "converters", "device", "on_cpu",
        "options", "own", "reuse", "settings", "tid_ndim",
    )  # fmt: skip

    def __init__(
        self, kernel: Any, device: Device, backend: Backend, settings: tuple, backend_arg: Any
    ) -> None:
        self.device = device
        self.alias = device.alias
        self.on_cpu = device.is_cpu
        self.backend = backend
        #: The ``backend`` argument of the launches this plan serves (a name, None or a Backend).
        self.backend_arg = backend_arg
        self.settings = settings
        self.own = dict(getattr(kernel, "options", None) or {})
        # The module's options (set_module_options) fill in what the kernel leaves unset;
        # process-wide debug settings (kdsl.config) resolve into them: they key the cache.
        self.options = _modules.kernel_options(kernel)
        self.compiled = _compiled(kernel, backend, config.compile_options(self.options))
        load_support(backend)  # once per process: e.g. the cpu backend's native pool
        self.converters = [
            _converter(kernel, i, n, t, device)
            for i, (n, t) in enumerate(zip(kernel.arg_names, kernel.arg_types))
        ]
        #: Plain launches with unchanged arguments reuse their packed form.
        self.reuse = LaunchReuse(backend, self.compiled, kernel.arg_types, self.converters)
        self.tid_ndim = getattr(kernel, "tid_ndim", 0) or 0


_PLAN_ATTR = "_kdsl_plans"
_LAST_ATTR = "_kdsl_last_plan"
_VALUE_AT_ATTR = "_kdsl_value_at"


def launch_plan(kernel: Any, device: Any, backend: Any) -> _Plan:
    """The cached plan for ``kernel`` on ``device`` with ``backend``.

    Plans are looked up by device, backend and the debug settings of ``kdsl.config``,
    and dropped when the kernel's options change, so a hit costs a dict lookup. The
    plan used last is tried first, when ``device`` names its device exactly (its
    ``Device`` or its full alias: a bare "cuda" follows the current device) and
    ``backend`` is the same argument.
    """
    settings = (config.mode, config.verify_fp, _modules.version)
    plan = getattr(kernel, _LAST_ATTR, None)
    if (
        plan is not None
        and (device is plan.device or device == plan.alias)
        and backend is plan.backend_arg
        and plan.settings == settings
        and plan.own == (getattr(kernel, "options", None) or {})
    ):
        return plan
    dev = get_device(device)
    key = (dev.alias, backend if isinstance(backend, str | None) else id(backend))
    plans = getattr(kernel, _PLAN_ATTR, None)
    if plans is None:
        plans = {}
        setattr(kernel, _PLAN_ATTR, plans)
    plan = plans.get(key)
    if (
        plan is None
        or plan.settings != settings
        or plan.own != (getattr(kernel, "options", None) or {})
    ):
        plan = plans[key] = _Plan(kernel, dev, _resolve_backend(backend, dev), settings, backend)
    setattr(kernel, _LAST_ATTR, plan)
    return plan


def forget(kernel: Any) -> None:
    """Drop the compiled code and launch plans cached on ``kernel``."""
    for attr in (_CACHE_ATTR, _PLAN_ATTR, _LAST_ATTR, _VALUE_AT_ATTR):
        if hasattr(kernel, attr):
            delattr(kernel, attr)


_KDSL_DIR = str(Path(__file__).resolve().parents[1])


def _user_frame() -> Any:
    """The innermost frame outside the kdsl package (the user's ``launch`` call)."""
    f = sys._getframe(1)
    while f is not None and str(Path(f.f_code.co_filename).resolve()).startswith(_KDSL_DIR):
        f = f.f_back
    return f


def kernel_definition(kernel: Any) -> Loc | None:
    """Where ``kernel``'s ``def`` line is (None when its source cannot be read)."""
    fn = getattr(kernel, "fn", None)
    if fn is None:
        return None
    try:
        lines, start = inspect.getsourcelines(fn)
    except (OSError, TypeError):
        return None
    for k, text in enumerate(lines):
        stripped = text.lstrip()
        if stripped.startswith(("def ", "async def ")):
            col = len(text) - len(stripped) + 1
            return Loc(inspect.getsourcefile(fn) or fn.__code__.co_filename, start + k, col)
    return None


def locate_launch_error(err: KdslLaunchError, kernel: Any) -> KdslLaunchError:
    """``err`` pointing at the user's ``launch`` call and at the kernel's definition."""
    if err.loc is None:
        frame = _user_frame()
        if frame is not None:
            col, end_line, end_col = 1, None, None
            try:
                pos = inspect.getframeinfo(frame, context=0).positions
                if pos is not None and pos.col_offset is not None:
                    col, end_line = pos.col_offset + 1, pos.end_lineno
                    end_col = pos.end_col_offset + 1 if pos.end_col_offset is not None else None
            except (AttributeError, ValueError):  # no column table (Python < 3.11)
                pass
            err.loc = Loc(frame.f_code.co_filename, frame.f_lineno, col, end_line, end_col)
            err.func = frame.f_code.co_name
    if getattr(err, "kernel_loc", None) is None:
        err.kernel_loc = kernel_definition(kernel)
        err.kernel_name = _kernel_name(kernel)
    return err


def _converter(kernel: Any, index: int, name: str, t: Any, device: Device) -> Any:
    """A function converting one argument, with a fast path for the common case.

    The fast path takes a kdsl array of exactly the parameter's type on the launch
    device, or a Python/NumPy scalar of the parameter's own kind; everything else
    goes through ``convert`` (which also produces every error message).
    """

    def slow(v: Any) -> Any:
        return _convert_one(kernel, index, name, t, v, device)

    if isinstance(t, T.ArrayType):
        dtype, ndim = t.dtype, t.ndim

        def conv_array(v: Any) -> Any:
            if (
                isinstance(v, array)
                and (v._device is device or v._device == device)
                and v._ndim == ndim
                and (v._t is dtype or v._t == dtype)
            ):
                return v._buf
            if (  # from_torch(..., return_ctype=True)
                type(v) is ArrayDescriptor
                and v.device is device
                and v.ndim == ndim
                and (v.dtype is dtype or v.dtype == dtype)
            ):
                return v.buf
            return slow(v)

        return conv_array
    if isinstance(t, T.ScalarType) and not t.is_bool:
        np_type = t.np_dtype.type
        if t.is_float:

            def conv_float(v: Any) -> Any:
                tv = type(v)
                if tv is np_type:
                    return v
                if tv is float or tv is int:
                    return np_type(v)
                return slow(v)

            return conv_float
        info = np.iinfo(t.np_dtype)
        lo, hi = int(info.min), int(info.max)

        def conv_int(v: Any) -> Any:
            tv = type(v)
            if tv is np_type:
                return v
            if tv is int and lo <= v <= hi:
                return np_type(v)
            return slow(v)

        if t == T.U64:  # maybe an object id (a mesh's, a BVH's): it must be on this device

            def conv_id(v: Any) -> Any:
                out = conv_int(v)
                wrong = foreign_id(int(out), device.alias)
                if wrong is not None:
                    raise launch_error(_kernel_name(kernel), index, name, wrong)
                return out

            return conv_id
        return conv_int
    if isinstance(t, T.VectorType | T.MatrixType):
        return _composite_converter(t, slow)
    return slow


#: Converted vectors and matrices kept per parameter, by value (cleared when full).
MAX_COMPOSITES = 64


def _composite_converter(t: T.Type, slow: Any) -> Any:
    """The converter of a vector or matrix parameter: a kdsl value of exactly ``t``'s
    class, dtype and shape is converted once per distinct value (its bytes) and the
    read-only result reused, so a launch passing the same ``vec3`` every step skips the
    general conversion; anything else goes through ``slow``."""
    dtype, shape = T.elem_type(t).np_dtype, T.value_shape(t)
    done: dict[bytes, np.ndarray] = {}
    classes: set[type] = set()

    def conv_composite(v: Any) -> Any:
        tv = type(v)
        if tv not in classes:
            if getattr(tv, "__kdsl_type__", None) != t or not issubclass(tv, np.ndarray):
                return slow(v)
            classes.add(tv)
        if v.dtype != dtype or v.shape != shape:
            return slow(v)
        key = v.tobytes()
        out = done.get(key)
        if out is None:
            out = slow(v)
            out.flags.writeable = False
            if len(done) >= MAX_COMPOSITES:
                done.clear()
            done[key] = out
        return out

    return conv_composite


@dataclass(eq=False)
class Launch:
    """A recorded launch (``record_cmd=True``) that relaunches with little Python work.

    The arguments are converted and packed once, when recorded and when an array
    parameter or the grid changes; ``launch()`` then goes straight to the backend's
    prepared call. A new scalar, vector or matrix argument is written into the packed
    form in place (``Backend.prepare_patchable``, where the backend has it; else the
    launch is packed again, ``Backend.prepare``). ``params`` are the converted arguments.
    """

    kernel: Any
    backend: Backend
    compiled: CompiledKernel
    dims: tuple[int, ...]
    params: list
    device: Device
    stream: Any
    #: Per parameter, the launch plan's converter (its fast path for the common
    #: arguments, ``convert`` for the rest); None: ``convert`` for every argument.
    converters: Any = field(default=None, repr=False)
    _run: Any = field(default=None, init=False, repr=False)
    #: Writes the by-value arguments into ``_run``'s packed form (None: repack instead).
    _write: Any = field(default=None, init=False, repr=False)
    #: The arguments ``_run`` was packed with (its buffers stay alive while it may run).
    _held: Any = field(default=None, init=False, repr=False)
    #: The indices of the by-value parameters (``by_value_indices``).
    _value_at: list = field(default_factory=list, init=False, repr=False)

    def __post_init__(self) -> None:
        self._value_at = _value_indices(self.kernel)

    def set_param_at_index(self, index: int, value: Any) -> None:
        """Replace argument ``index`` (checked like ``launch`` checks it)."""
        names, types = self.kernel.arg_names, self.kernel.arg_types
        if not 0 <= index < len(types):
            raise KdslLaunchError(
                f"kernel '{_kernel_name(self.kernel)}' has {len(types)} parameters; "
                f"there is no index {index}"
            )
        try:
            convs = self.converters
            if convs is not None:  # (a changed scalar: a merge's run length, a time step)
                self.params[index] = convs[index](value)
            else:
                self.params[index] = _convert_one(
                    self.kernel, index, names[index], types[index], value, self.device
                )
        except KdslLaunchError as e:
            raise locate_launch_error(e, self.kernel) from None
        write = self._write
        if write is None or self._run is None or index not in self._value_at:
            self._run = None
            return
        try:  # the packed form takes the new value in place
            write([self.params[i] for i in self._value_at])
        except KdslLaunchError as e:
            self._run = None  # maybe half-written: pack afresh
            raise locate_launch_error(e, self.kernel) from None

    def set_param_by_name(self, name: str, value: Any) -> None:
        """Replace the argument of parameter ``name``."""
        names = list(self.kernel.arg_names)
        if name not in names:
            raise KdslLaunchError(f"kernel '{_kernel_name(self.kernel)}' has no parameter '{name}'")
        self.set_param_at_index(names.index(name), value)

    def set_params(self, values: Sequence[Any]) -> None:
        """Replace every argument at once (in parameter order)."""
        for i, v in enumerate(values):
            self.set_param_at_index(i, v)

    def set_dim(self, dim: Any) -> None:
        """Change the launch grid."""
        dims = normalize_dim(dim, _kernel_name(self.kernel))
        check_tid(self.kernel, dims)
        self.dims = dims
        self._run = None

    def launch(self, stream: Any = None) -> None:
        """Run the recorded launch (on ``stream`` when given, else the recorded one)."""
        if stream is not None and stream is not self.stream:
            self.backend.launch(self.compiled, self.dims, self.params, stream)
            return
        run = self._run
        if run is None:
            run = self._prepare()
        run()

    def _prepare(self) -> Any:
        """Pack the launch, patchable where the backend can make it so."""
        made = None
        if self._value_at:
            made = self.backend.prepare_patchable(
                self.compiled, self.dims, self.params, self.stream, self._value_at
            )
        if made is None:
            self._write = self._held = None
            self._run = self.backend.prepare(self.compiled, self.dims, self.params, self.stream)
        else:
            self._run, self._write = made
            self._held = list(self.params)  # ``params`` is public: it may be reassigned
        return self._run


def _value_indices(kernel: Any) -> list[int]:
    """``by_value_indices`` of ``kernel``'s parameters, worked out once per kernel (a
    build prepares several launches of each of its kernels); a copy, so a caller may
    keep it."""
    held = getattr(kernel, _VALUE_AT_ATTR, None)
    if held is None or held[0] is not kernel.arg_types:
        held = (kernel.arg_types, by_value_indices(kernel.arg_types))
        setattr(kernel, _VALUE_AT_ATTR, held)
    return list(held[1])


def _convert_one(kernel: Any, index: int, name: str, t: Any, value: Any, device: Device) -> Any:
    try:
        return convert(t, value, device)
    except ArgError as e:
        raise launch_error(_kernel_name(kernel), index, name, str(e)) from None


def _value_type(v: Any) -> T.Type | None:
    """The kernel type of a launch argument, inferred as Warp does; None if unknown."""
    if type(v) in _PY_TYPES:
        return _PY_TYPES[type(v)]
    if isinstance(v, np.generic):
        return T.scalar_from_numpy(v.dtype)
    try:
        t = getattr(v, "__kdsl_type__", None)  # arrays, indexed arrays, vectors, structs
    except TypeError:  # an array of dtype=Any
        return None
    if isinstance(t, T.Type):
        return t
    if isinstance(v, np.ndarray) and v.dtype.kind in "biuf":
        return T.ArrayType(T.scalar_from_numpy(v.dtype), v.ndim)
    return None


_PY_TYPES = {bool: T.BOOL, int: T.I32, float: T.F32}


def instance_for(kernel: Any, args: Sequence[Any], n_in: int = -1, n_out: int = 0) -> Any:
    """The instance of a generic kernel for the types of ``args`` (made and cached once)."""
    names, params = list(kernel.arg_names), list(kernel.arg_types)
    if len(args) != len(params):
        given = f" ({n_in} inputs, {n_out} outputs)" if n_in >= 0 else ""
        raise KdslLaunchError(
            f"kernel '{_kernel_name(kernel)}' takes {len(params)} arguments "
            f"({', '.join(names)}) but {len(args)} were given{given}"
        )
    types = []
    for i, (name, t, v) in enumerate(zip(names, params, args)):
        if isinstance(t, T.Type):
            types.append(t)
            continue
        got = _value_type(v)
        if got is None or not t.matches(got):
            what = f"a {got}" if got is not None else type(v).__name__
            raise launch_error(
                _kernel_name(kernel), i, name,
                f"the generic parameter is {t}; cannot instantiate it for {what}",
            )  # fmt: skip
        types.append(got)
    return kernel.instance(types)


def launch(
    kernel: Any,
    dim: Any,
    inputs: Sequence[Any] = (),
    outputs: Sequence[Any] = (),
    adj_inputs: Sequence[Any] | None = None,
    adj_outputs: Sequence[Any] | None = None,
    device: Any = None,
    stream: Any = None,
    adjoint: bool = False,
    record_tape: bool = True,
    record_cmd: bool = False,
    max_blocks: int = 0,
    block_dim: int = 256,
    backend: Any = None,
) -> Launch | None:
    """Run ``kernel`` once per index of ``dim`` with ``inputs`` then ``outputs`` as arguments.

    ``dim`` is an int or a tuple of 1 to 4 ints. Arguments are checked against the
    kernel's parameters (count, dtype, ndim, device). With ``record_cmd=True`` the
    launch is not run but returned as a ``Launch`` to run (and rerun) later.

    While a ``kdsl.Tape`` is active the launch is recorded on it, unless
    ``record_tape=False``. ``adjoint=True`` runs the kernel's adjoint instead:
    ``adj_inputs``/``adj_outputs`` hold one entry per input/output, the gradient
    array of an array argument (input gradients receive +=, output gradients hold
    the incoming gradient) or None for no gradient.
    """
    # One try, no wrapper: a kdsl error leaves with the user's frames only (zero cost
    # until something is raised; launch is on the hot path).
    try:
        if adjoint:
            _launch_adjoint(
                kernel, dim, inputs, outputs, adj_inputs, adj_outputs, device, stream, backend,
                record_cmd,
            )  # fmt: skip
            return None
        if type(dim) is int and dim >= 0:
            dims: tuple[int, ...] = (dim,)
        else:
            dims = normalize_dim(dim, _kernel_name(kernel))
        args = [*inputs, *outputs] if outputs else inputs
        # A kernel with plans is not generic (a generic one's instances hold them).
        if getattr(kernel, _PLAN_ATTR, None) is None and getattr(kernel, "is_generic", False):
            kernel = instance_for(kernel, args, len(inputs), len(outputs))
        plan = launch_plan(kernel, device, backend)
        convs = plan.converters
        if len(args) != len(convs):
            names = list(kernel.arg_names)
            raise KdslLaunchError(
                f"kernel '{_kernel_name(kernel)}' takes {len(convs)} arguments "
                f"({', '.join(names)}) but {len(args)} were given ({len(inputs)} inputs, "
                f"{len(outputs)} outputs)"
            )
        dev = plan.device
        rec = known = None
        if _graphs.ACTIVE and not record_cmd:  # a capture: repeated launches skip the checks
            stream = resolve_stream(dev, stream)
            rec = _graphs.recording(dev, stream)
        elif not record_cmd and _timing.RECORDING is None:
            if stream is None and not plan.on_cpu:
                stream = current_stream(dev)  # resolve_stream, inline
            reuse = plan.reuse
            if (reuse.same is not None and reuse.relaunch(args, dims, stream)) or (
                reuse.tokens is not None
                and not reuse.bypass
                and (known := reuse.object_key(args, dims, stream)) is not None
                and reuse.run_known(known)
            ):  # argument objects launched before: nothing to convert or key
                if _tape.ACTIVE and record_tape:
                    _record_on_tape(kernel, dims, inputs, outputs, dev, max_blocks, block_dim,
                                    backend, stream)  # fmt: skip
                return None
        converted = None if rec is None else rec.converted(plan, args)
        if converted is None:
            converted = [conv(v) for conv, v in zip(convs, args)]
            if rec is not None:
                rec.remember(plan, args, converted)
        if len(dims) > 1 or plan.tid_ndim > 1:
            check_tid(kernel, dims)
        stream = resolve_stream(dev, stream)
        if record_cmd:
            return Launch(kernel, plan.backend, plan.compiled, dims, converted, dev, stream,
                          plan.converters)  # fmt: skip
        if rec is not None:
            rec.record_launch(plan, dims, converted, stream)
        elif _timing.RECORDING is None:
            plan.reuse.launch(dims, converted, stream, args, (known, args))
        else:
            _timing.timed_launch(
                plan.backend, plan.compiled, dims, converted, stream, dev,
                f"forward kernel {_kernel_name(kernel)}",
            )  # fmt: skip
        if _tape.ACTIVE and record_tape:
            _record_on_tape(
                kernel, dims, inputs, outputs, dev, max_blocks, block_dim, backend, stream
            )
        return None
    except KdslError as e:
        if isinstance(e, KdslLaunchError):
            locate_launch_error(e, kernel)
            e.__suppress_context__ = True
        hide_internal_frames(e)
        raise


def _record_on_tape(
    kernel: Any, dims: tuple, inputs: Sequence[Any], outputs: Sequence[Any], dev: Device,
    max_blocks: int, block_dim: int, backend: Any, stream: Any,
) -> None:  # fmt: skip
    """Record a forward launch on the active tape, with the user's calling frame."""
    caller = sys._getframe(2)  # launch()'s caller
    _tape.ACTIVE[-1].record_launch(
        kernel, dims, inputs, outputs, dev, max_blocks, block_dim,
        {"caller": {"file": caller.f_code.co_filename, "lineno": caller.f_lineno,
                    "func": caller.f_code.co_name}},
        backend, stream,
    )  # fmt: skip


def _adjoint_list(adj: Sequence[Any] | None, primal: Sequence[Any], what: str, name: str) -> list:
    # No adjoints given means no gradient wanted for any of them.
    if adj is None or (len(adj) == 0 and len(primal) > 0):
        return [None] * len(primal)
    if len(adj) != len(primal):
        raise KdslLaunchError(
            f"kernel '{name}': adjoint launch got {len(adj)} adj_{what} for {len(primal)} {what}; "
            f"give one entry per {what[:-1]} (None for no gradient)"
        )
    return list(adj)


def _launch_adjoint(
    kernel: Any,
    dim: Any,
    inputs: Sequence[Any],
    outputs: Sequence[Any],
    adj_inputs: Sequence[Any] | None,
    adj_outputs: Sequence[Any] | None,
    device: Any,
    stream: Any,
    backend: Any,
    record_cmd: bool,
) -> None:
    """``launch(adjoint=True)``: the adjoint of one launch (never recorded on a tape)."""
    name = _kernel_name(kernel)
    if record_cmd:
        raise KdslLaunchError(
            f"kernel '{name}': record_cmd=True is not supported with adjoint=True"
        )
    if getattr(kernel, "is_generic", False):
        try:
            kernel = instance_for(kernel, [*inputs, *outputs], len(inputs), len(outputs))
        except KdslLaunchError as e:
            raise locate_launch_error(e, kernel) from None
    adj = _adjoint_list(adj_inputs, inputs, "inputs", name)
    adj += _adjoint_list(adj_outputs, outputs, "outputs", name)
    from kdsl.runtime.adjoint import launch_adjoint

    launch_adjoint(
        kernel, dim, [*inputs, *outputs], adj, device=device, stream=stream, backend=backend
    )
