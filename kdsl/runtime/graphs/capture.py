"""Warp's graph API: ``capture_begin`` / ``capture_end`` / ``capture_launch``,
``ScopedCapture``, ``capture_if`` / ``capture_while``, ``capture_save`` / ``capture_load``.

While a capture is open, work issued for its device (and, on CUDA, its stream) is
recorded, not run: kernel launches (forward and adjoint), ``kdsl.copy``, fills and
allocations. On CUDA the stream itself captures (CuPy stream capture, relaxed mode
by default, since CuPy's pool calls ``cudaMalloc`` on a miss); on the CPU each launch
is prepared once (arguments converted and packed) and replayed by a Python loop of
native calls. Host reads and synchronizations raise before they reach the driver, so
a refused call leaves the capture and the stream usable. See docs/runtime.md.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from typing import Any

import numpy as np

from kdsl import config
from kdsl.compiler import check_pipeline
from kdsl.errors import KdslCapabilityError, KdslError, KdslRuntimeError
from kdsl.ir import types as T
from kdsl.runtime.array import array
from kdsl.runtime.device import Device, cupy, get_device
from kdsl.runtime.graphs import state
from kdsl.runtime.graphs.graph import (
    ConditionReader,
    Graph,
    call_node,
    detached,
    if_node,
    numpy_root,
    segment_node,
    while_node,
)
from kdsl.runtime.stream import Stream, get_stream


class CaptureMode(enum.IntEnum):
    """CUDA's stream capture modes (``cudaStreamCaptureMode``), as in Warp."""

    GLOBAL = 0
    THREAD_LOCAL = 1
    RELAXED = 2


#: Argument objects whose identity fixes their value (so a repeated launch may reuse
#: the conversion); structs and lists can change between two launches.
_IMMUTABLE = (int, float, bool, np.generic)

#: CuPy memory objects kdsl's pool allocates (others wrap foreign memory).
_CUPY_OWNED = ("PooledMemory", "Memory")


class Recording:
    """One open capture: its graph, its device and stream, and what it must keep."""

    def __init__(self, device: Device, stream: Stream | None, mode: int, parent: Any = None):
        self.device = device
        self.stream = stream
        self.mode = mode
        self.parent = parent
        self.top: Recording = parent.top if parent is not None else self
        self.graph = Graph(device)
        self.segment_open = False
        if parent is None:
            self.owned_ids: set[int] = set()
            self.args_cache: dict[tuple, tuple] = {}
            self.checked: dict[int, bool] = {}

    # --- CUDA segments -------------------------------------------------------------
    def begin_segment(self) -> None:
        """Start capturing the stream into a new CUDA graph (no-op on the CPU)."""
        if self.device.is_cpu:
            return
        cp = cupy()
        with cp.cuda.Device(self.device.ordinal):
            self.stream.cupy.begin_capture(mode=self.mode)
        self.segment_open = True

    def end_segment(self, keep: bool = True) -> None:
        """Stop capturing the stream; the CUDA graph becomes a node unless ``keep`` is False."""
        if not self.segment_open:
            return
        self.segment_open = False
        cp = cupy()
        try:
            with cp.cuda.Device(self.device.ordinal):
                g = self.stream.cupy.end_capture()
        except Exception as e:  # the driver invalidated the capture
            if not keep:
                return
            raise KdslRuntimeError(
                f"the CUDA graph capture on {self.stream} failed: {e}. The stream is usable "
                f"again; capture anew"
            ) from None
        if keep:
            self.graph.nodes.append(segment_node(g, self.device.ordinal))

    # --- what the capture holds ----------------------------------------------------
    def own(self, obj: Any, ident: Any = None) -> None:
        """Keep ``obj`` (an allocation made during the capture) alive with the graph."""
        self.top.graph.owned.append(obj)
        self.top.owned_ids.add(id(obj if ident is None else ident))

    def watch(self, buf: Any, what: str) -> Any:
        """Note the memory of buffer ``buf`` used by the graph; on the CPU, a detached view."""
        if self.device.is_cpu:
            if not isinstance(buf, np.ndarray) or buf.size == 0:
                return buf
            root = numpy_root(buf)
            if root.base is not None:  # foreign memory (DLPack, a buffer object): keep it
                self.top.graph.owned.append(buf)
            elif id(root) not in self.top.owned_ids:
                self.graph.watch.add(root, what)
            else:
                return buf
            return detached(buf)
        if buf.size == 0:
            return buf
        mem = buf.data.mem
        if type(mem).__name__ in _CUPY_OWNED:
            if id(mem) not in self.top.owned_ids:
                self.graph.watch.add(mem, what)
        else:
            self.top.graph.owned.append(buf)
        return buf

    def _watch_args(self, types: list, values: list, name: str) -> list:
        out = []
        for i, (t, v) in enumerate(zip(types, values)):
            if isinstance(t, T.ArrayType):
                v = self.watch(v, f"argument {i} (an array of {t.dtype}) of kernel '{name}'")
            elif isinstance(t, T.StructType) and isinstance(v, tuple):
                v = tuple(self._watch_args([ft for _, ft in t.fields], list(v), name))
            out.append(v)
        return out

    # --- launches ------------------------------------------------------------------
    def converted(self, plan: Any, args: Any) -> list | None:
        """The conversion of an earlier launch of ``plan`` with these very arguments."""
        hit = self.top.args_cache.get((id(plan), *map(id, args)))
        return None if hit is None else hit[1]

    def remember(self, plan: Any, args: Any, converted: list) -> None:
        """Let later launches of ``plan`` with these argument objects skip the checks."""
        if all(isinstance(a, array) or type(a) in _IMMUTABLE for a in args):
            # The tuple keeps the arguments alive, so their ids stay theirs.
            self.top.args_cache[(id(plan), *map(id, args))] = (tuple(args), converted)

    def record_launch(self, plan: Any, dims: tuple, converted: list, stream: Any) -> None:
        """Capture one launch (converted arguments) of ``plan`` over ``dims``."""
        compiled = plan.compiled
        name = compiled.metadata.get("name") or compiled.symbol
        types = compiled.metadata.get("arg_types")
        if types is None:
            func = compiled.module.get_func(compiled.symbol)
            types = compiled.metadata["arg_types"] = [a.type for a in func.regions[0].block.args]
        if self.device.is_cpu:
            args = self._watch_args(types, list(converted), name)
            run = plan.backend.prepare(compiled, dims, args, None)
            self.graph.nodes.append(call_node(run))
            return
        checked = self.top.checked.get(id(plan))
        if checked is None:
            opts = config.compile_options(plan.options)
            checked = self.top.checked[id(plan)] = bool(check_pipeline(opts))
        if checked:
            raise KdslRuntimeError(
                f"kernel '{name}' is compiled with debug checks (bounds or NaN checks), which "
                f"read an error record on the host after each launch; that cannot be captured. "
                f"Capture a release build (kdsl.config.mode = 'release', no verify_fp)"
            )
        plan.backend.launch(compiled, dims, converted, stream)
        self._watch_args(types, list(converted), name)

    def record_host(self, fn: Callable[..., None], *bufs: Any) -> None:
        """Record a CPU operation ``fn(*bufs)`` (a copy, a fill) to run at replay."""
        views = [self.watch(b, "an array copied or filled in the capture") for b in bufs]
        self.graph.nodes.append(call_node(lambda: fn(*views)))

    def append_graph(self, graph: Graph) -> None:
        """Replay ``graph`` at this point of the capture (``capture_launch`` while capturing)."""
        self.end_segment()
        self.graph.nodes.extend(graph.nodes)
        self.graph.watch.merge(graph.watch)
        self.graph.children.append(graph)
        self.begin_segment()

    def capture_branch(self, branch: Any, what: str, kwargs: dict) -> Graph:
        """``branch`` (a callable, run now under a nested capture, or a Graph) as a Graph."""
        if isinstance(branch, Graph):
            _check_graph_device(branch, self.device, what)
            return branch
        if not callable(branch):
            raise KdslError(
                f"{what} must be a callable or a kdsl.Graph, not {type(branch).__name__}"
            )
        sub = Recording(self.device, self.stream, self.mode, parent=self)
        sub.begin_segment()
        state.ACTIVE.append(sub)
        try:
            branch(**kwargs)
        except BaseException:
            state.ACTIVE.remove(sub)
            sub.end_segment(keep=False)
            raise
        state.ACTIVE.remove(sub)
        sub.end_segment()
        sub.graph._ended = True
        return sub.graph


def _check_graph_device(graph: Graph, device: Device, what: str) -> None:
    if graph.device != device:
        raise KdslRuntimeError(
            f"{what} is a graph captured on '{graph.device}'; it cannot run on '{device}'"
        )


# --- the CUDA allocator hook: allocations during a capture belong to its graph -----------
_saved_allocator: list[Any] = []


def _install_allocator() -> None:
    cp = cupy()
    previous = cp.cuda.get_allocator()

    def allocate(size: int) -> Any:
        mp = previous(size)
        ptr = cp.cuda.get_current_stream().ptr
        for rec in reversed(state.ACTIVE):
            if rec.stream is not None and rec.stream.cuda_stream == ptr:
                rec.own(mp, mp.mem)  # never back to the pool while the graph may replay
                break
        return mp

    _saved_allocator.append(previous)
    cp.cuda.set_allocator(allocate)


def _restore_allocator() -> None:
    if _saved_allocator and not any(r.device.is_cuda for r in state.ACTIVE):
        cupy().cuda.set_allocator(_saved_allocator.pop())


# --- the public API ---------------------------------------------------------------
def capture_begin(
    device: Any = None,
    stream: Stream | None = None,
    force_module_load: bool | None = None,
    external: bool = False,
    apic: bool = False,
    capture_mode: CaptureMode = CaptureMode.RELAXED,
) -> None:
    """Start recording the work issued on ``device`` (its current stream, or ``stream``).

    Launches, copies, fills and allocations are recorded, not run, until
    ``capture_end`` returns them as a ``Graph``. ``capture_mode`` is CUDA's capture
    mode (relaxed by default: CuPy's pool may call ``cudaMalloc``); ``external`` and
    ``apic`` (Warp's foreign captures and serialization) are not supported.
    """
    if stream is not None:
        if not isinstance(stream, Stream):
            raise KdslError(
                f"capture_begin(): stream must be a kdsl.Stream, not {type(stream).__name__}"
            )
        device = stream.device
    dev = get_device(device)
    if external:
        raise KdslCapabilityError(
            "capture_begin(external=True): kdsl cannot join a capture another library "
            "started; begin the capture with kdsl"
        )
    if apic:
        raise KdslCapabilityError(
            "capture_begin(apic=True): kdsl cannot serialize graphs (see capture_save)"
        )
    if dev.is_cpu:
        if state.on_device(dev) is not None:
            raise KdslRuntimeError("a graph capture is already open on 'cpu'; end it first")
    else:
        stream = stream or get_stream(dev)
        if state.recording(dev, stream) is not None or stream.is_capturing:
            raise KdslRuntimeError(
                f"a graph capture is already open on {stream}; end it (capture_end) before "
                f"beginning another, or capture on another stream"
            )
    if force_module_load:
        from kdsl.runtime.modules import force_load

        force_load(dev)
    rec = Recording(dev, None if dev.is_cpu else stream, int(capture_mode))
    if dev.is_cuda and not any(r.device.is_cuda for r in state.ACTIVE):
        _install_allocator()
    try:
        rec.begin_segment()
    except Exception as e:
        _restore_allocator()
        raise KdslRuntimeError(f"cannot begin a CUDA graph capture on {stream}: {e}") from None
    state.ACTIVE.append(rec)


def _find(device: Any, stream: Stream | None) -> Recording:
    if stream is not None:
        rec = state.recording(stream.device, stream)
        where = str(stream)
    elif device is None and (cpu := state.on_device(get_device("cpu"))) is not None:
        rec, where = cpu, "cpu"  # as in Warp, an open CPU capture ends first
    else:
        dev = get_device(device)
        rec = state.recording(dev, None if dev.is_cpu else get_stream(dev))
        where = f"'{dev}'"
    if rec is None:
        raise KdslRuntimeError(f"capture_end(): no graph capture is open on {where}")
    if rec.parent is not None:
        raise KdslRuntimeError(
            "capture_end() inside a capture_if/capture_while branch: end the capture after "
            "the branch returns"
        )
    return rec


def capture_end(device: Any = None, stream: Stream | None = None) -> Graph:
    """End the capture open on ``device`` (or ``stream``) and return its ``Graph``."""
    rec = _find(device, stream)
    state.ACTIVE.remove(rec)
    try:
        rec.end_segment()
    finally:
        _restore_allocator()
    rec.args_cache.clear()
    rec.checked.clear()
    rec.graph._ended = True
    return rec.graph


def capture_launch(graph: Graph, stream: Stream | None = None) -> None:
    """Replay ``graph`` (on ``stream``, by default its device's current stream).

    Inside an open capture on the same device and stream the graph's work is
    appended to that capture.
    """
    if not isinstance(graph, Graph):
        raise KdslError(f"capture_launch() takes a kdsl.Graph, not {type(graph).__name__}")
    if not graph._ended:
        raise KdslRuntimeError("capture_launch(): the graph's capture is still open; end it first")
    dev = graph.device
    if dev.is_cpu:
        rec = state.on_device(dev)
        if rec is not None:
            rec.append_graph(graph)
        else:
            graph.replay(None)
        return
    if stream is None:
        stream = get_stream(dev)
    elif not isinstance(stream, Stream):
        raise KdslError(
            f"capture_launch(): stream must be a kdsl.Stream, not {type(stream).__name__}"
        )
    if stream.device != dev:
        raise KdslRuntimeError(
            f"capture_launch(): the graph was captured on '{dev}' and cannot run on a stream "
            f"of '{stream.device}'; capture it again on that device"
        )
    rec = state.recording(dev, stream)
    if rec is not None:
        rec.append_graph(graph)
        return
    graph.replay(stream)


class ScopedCapture:
    """``with ScopedCapture(device) as capture:`` records the block; then ``capture.graph``.

    If the block raises, the capture is ended and discarded (the stream stays usable)
    and the block's exception propagates.
    """

    def __init__(
        self,
        device: Any = None,
        stream: Stream | None = None,
        force_module_load: bool | None = None,
        external: bool = False,
        apic: bool = False,
        capture_mode: CaptureMode = CaptureMode.RELAXED,
    ) -> None:
        self.device = device
        self.stream = stream
        self.force_module_load = force_module_load
        self.external = external
        self.apic = apic
        self.capture_mode = capture_mode
        self.active = False
        self.graph: Graph | None = None

    def __enter__(self) -> ScopedCapture:
        capture_begin(self.device, self.stream, self.force_module_load, self.external,
                      self.apic, self.capture_mode)  # fmt: skip
        self.active = True
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if not self.active:
            return
        self.active = False
        try:
            self.graph = capture_end(self.device, self.stream)
        except KdslError:
            if exc_type is None:
                raise


def is_conditional_graph_supported() -> bool:
    """Whether captures build CUDA conditional nodes (False: see docs/runtime.md, Graphs).

    ``capture_if`` and ``capture_while`` still work inside captures on every device:
    the graph is split at the conditional, whose condition is read on replay.
    """
    return False


def _condition(condition: Any, what: str) -> None:
    if not isinstance(condition, array) or condition._t != T.I32 or condition.size < 1:
        raise KdslError(
            f"{what}: the condition must be a kdsl array of int32 (its element 0 is the "
            f"condition), not {type(condition).__name__}"
            + (f" of {condition.dtype.__name__}" if isinstance(condition, array) else "")
        )


def _run_branch(branch: Any, what: str, stream: Any, kwargs: dict) -> None:
    if isinstance(branch, Graph):
        capture_launch(branch, stream=stream)
    elif callable(branch):
        branch(**kwargs)
    else:
        raise KdslError(f"{what} must be a callable or a kdsl.Graph, not {type(branch).__name__}")


def _stream_for(condition: array, stream: Stream | None) -> Stream | None:
    if condition.device.is_cpu:
        return None
    return stream or get_stream(condition.device)


def capture_if(
    condition: array,
    on_true: Callable | Graph | None = None,
    on_false: Callable | Graph | None = None,
    stream: Stream | None = None,
    **kwargs: Any,
) -> None:
    """Run ``on_true`` if ``condition[0]`` is nonzero, else ``on_false`` (each a callable
    called with ``kwargs``, or a Graph). Inside a capture the choice is made at each replay.
    """
    if on_true is None and on_false is None:
        return
    _condition(condition, "capture_if()")
    dev = condition.device
    s = _stream_for(condition, stream)
    rec = state.recording(dev, s) if state.ACTIVE else None
    if rec is None:
        value = ConditionReader(condition._buf, dev).value(s)
        branch = on_true if value else on_false
        if branch is not None:
            _run_branch(branch, "capture_if() branch", s, kwargs)
        return
    reader = ConditionReader(rec.watch(condition._buf, "the condition array of capture_if"), dev)
    rec.end_segment()
    try:
        yes = None if on_true is None else rec.capture_branch(on_true, "on_true", kwargs)
        no = None if on_false is None else rec.capture_branch(on_false, "on_false", kwargs)
    except BaseException:
        rec.begin_segment()  # the outer capture goes on, without the conditional
        raise
    rec.graph.children.extend(g for g in (yes, no) if g is not None)
    rec.graph.nodes.append(if_node(reader, yes, no))
    rec.begin_segment()


def capture_while(
    condition: array, while_body: Callable | Graph, stream: Stream | None = None, **kwargs: Any
) -> None:
    """Run ``while_body`` (a callable called with ``kwargs``, or a Graph) while
    ``condition[0]`` is nonzero; the body must update the condition. Inside a capture
    the loop runs at each replay.
    """
    _condition(condition, "capture_while()")
    dev = condition.device
    s = _stream_for(condition, stream)
    rec = state.recording(dev, s) if state.ACTIVE else None
    if rec is None:
        reader = ConditionReader(condition._buf, dev)
        while reader.value(s):
            _run_branch(while_body, "capture_while() body", s, kwargs)
        return
    reader = ConditionReader(rec.watch(condition._buf, "the condition array of capture_while"), dev)
    rec.end_segment()
    try:
        body = rec.capture_branch(while_body, "while_body", kwargs)
    except BaseException:
        rec.begin_segment()
        raise
    rec.graph.children.append(body)
    rec.graph.nodes.append(while_node(reader, body))
    rec.begin_segment()


_NO_SAVE = (
    "kdsl cannot serialize graphs: a kdsl graph holds launches packed with this process's "
    "memory addresses and compiled code objects, and kdsl has no relocatable format that "
    "names arrays and kernels instead (Warp's .wrp). Capture the graph again in the "
    "process that replays it (a capture costs one step of ordinary launches)"
)


def capture_save(graph: Graph, path: str, inputs: Any = None, outputs: Any = None,
                 source_fallback: bool = False) -> None:  # fmt: skip
    """Warp's graph serialization; not supported by kdsl (raises ``KdslCapabilityError``)."""
    raise KdslCapabilityError(f"capture_save(): {_NO_SAVE}")


def capture_load(path: str, device: Any = None) -> Graph:
    """Warp's graph deserialization; not supported by kdsl (raises ``KdslCapabilityError``)."""
    raise KdslCapabilityError(f"capture_load(): {_NO_SAVE}")


def capture_load_from_bytes(data: Any, modules: Any = None, device: Any = None) -> Graph:
    """Warp's graph deserialization; not supported by kdsl (raises ``KdslCapabilityError``)."""
    raise KdslCapabilityError(f"capture_load_from_bytes(): {_NO_SAVE}")
