"""Packed-launch reuse: a plain ``launch`` with unchanged arguments skips packing.

A kernel launched again and again on the same arrays (a simulation step) would pack
the same descriptors every time. ``LaunchReuse`` keeps, per launch plan, a few
launches prepared by the backend (``Backend.prepare_reusable``: arguments packed
once, as ``record_cmd=True`` does) under a key made of everything the packed bytes
depend on:

- the grid and the stream, by identity (the entry holds the stream, so its id is not
  reused while the entry lives; a ``Stream`` hashes through CuPy, which costs about a
  microsecond; another device is another plan);
- per array argument, the identity of the converted buffer with its shape and strides
  (an array reallocated, resized or reshaped is a new buffer or a new shape);
- then per scalar, vector, matrix or handle, the exact bytes of the converted value (so
  ``-0.0`` and ``0.0``, or two NaN payloads, are different keys).

Struct arguments are not keyed (their fields may be mutated in place), so a kernel
with a struct parameter is always packed afresh. Arguments are still converted and
checked on every launch; only the packing is reused.

A prepared launch holds its buffers weakly: the reuse never keeps an array's memory
alive. A hit first checks that every buffer of the entry is still alive (an alive
object's ``id`` cannot belong to another), else the entry is dropped and the launch
packed again. A key is prepared only when seen a second time, so arguments that
change at every launch (a time step) cost a key lookup, not a prepare.

``relaunch`` goes one step further for the commonest loop, the same argument
*objects* launched again: when every argument of the launch that used the last
entry is a ``kdsl.array`` (whose buffer never changes: held weakly and compared by
identity) or an immutable Python or NumPy scalar (compared by identity), and the
grid and stream are those of that launch, the entry runs without converting or
keying anything. Only signatures of arrays and scalars take it (no structs,
vectors, matrices or object ids, whose values may change behind the same object or
name another device's object), and foreign arrays (a PyTorch tensor may be
re-pointed in place) never do.

``run_known`` serves the next commonest loop, a cycle of argument sets (a taped
flight launches one kernel on a different pair of arrays each step, and replays their
adjoints): a table of entries keyed by the argument *objects* (``object_key``): a
``kdsl.array`` by identity (the entry holds it weakly, as ``relaunch`` does), a
number by its value and kind (a Python number or the parameter's own NumPy type, the
latter as the Python number of its value, which hashes and compares faster; a float
zero by its sign, since ``-0.0 == 0.0``), a kdsl vector or matrix of the
parameter's exact class, dtype and shape by its bytes. Equal keys mean equal converted
values, so a hit runs the entry without converting anything; any other argument (a
struct, an object id, a foreign array, a tuple for a vector) makes the launch take the
general path. Entries are learnt when the general path runs a prepared launch.

A launch whose arrays recur but whose by-value arguments change at every step (the
simulation time, a frame number) never finds its key again. It takes a *patchable*
launch instead (``patches``, ``Backend.prepare_patchable``): one per key of its arrays,
grid and stream (the packed key's first ``split`` parts: no value bytes), made when
those come a second time with a new key, whose packed buffer gets the by-value
arguments (scalars of every width, bools, vectors, matrices, quaternions, handles)
written in place before each run. Its buffer is its own (exact entries are never
written, so ``entries``, ``known`` and ``relaunch``'s record of one stay right), a write
only ever follows a finished run (a cpu launch is synchronous, ``cuLaunchKernel``
copies its parameters), and only the thread that made it writes or runs it (another
thread's launch packs afresh). ``relaunch`` serves the loop without converting the
arrays: when the held arrays are the launch's but a by-value argument is another
object, it converts the by-value arguments only, writes them and runs the patchable
launch; a mutable vector is never held, so it is converted at every launch. A value of
a key that does recur (a cycle of argument sets) still gets its exact entry.

A launch whose key is new every time for its arrays too (new temporaries at every
step) gains nothing from keys and pays for them (the object key, the packed key, the
table of keys seen once). After ``MISS_STREAK`` such launches in a row the plan stops
keying for its next ``BYPASS`` launches (``bypass``, read by ``launch`` before the
object key): they go straight to the backend, as they would after a miss. Any reuse
(a patched launch too) resets the streak, so a kernel whose keys recur keeps its
tables.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from math import copysign
from threading import get_ident
from typing import Any

import numpy as np

from kdsl.backends.base import Backend, CompiledKernel
from kdsl.ir import types as T
from kdsl.runtime.array import array

#: Prepared launches kept per plan: double buffering needs two, a kernel taped over a
#: simulation's steps one per step (each step's arrays are kept for the backward pass;
#: its adjoint launches likewise). When full, entries whose buffers died are dropped,
#: and the table is cleared if that frees nothing.
MAX_ENTRIES = 128
#: Keys seen once, waiting for a second launch before they are prepared (larger than
#: ``MAX_ENTRIES``, so a cycle through that many argument sets gets prepared).
MAX_SEEN = 256
#: New keys in a row after which a plan stops keying: no hit in as many launches as
#: the seen table holds means no cycle the tables could learn.
MISS_STREAK = MAX_SEEN
#: Launches then run without keys before keying is tried again.
BYPASS = 4096
#: Patchable launches kept per plan (one per set of arrays, grid and stream); when full,
#: those whose buffers died are dropped, and the table is cleared if that frees nothing.
MAX_PATCHES = 64

_REF = weakref.ref

# Per parameter: how one converted argument adds to the key, and whether it is a
# buffer the entry must watch.
_ARRAY, _BYTES = 0, 1


def _same_kind(t: Any) -> bool:
    """Whether ``relaunch`` may compare arguments of parameter type ``t`` by identity."""
    if isinstance(t, T.ArrayType):
        return True
    return isinstance(t, T.ScalarType) and t != T.U64  # a u64 may be an object id


#: ``_token`` functions return this for an argument that cannot key a launch by itself.
_NO = object()
#: The keys of a float zero by its sign (``0 == -0.0``, so the number itself cannot key it).
_ZERO, _NEGATIVE_ZERO = object(), object()


def _token(t: Any) -> Callable[[Any], Any] | None:
    """How an argument object of parameter type ``t`` keys ``run_known``'s table (see the
    module docstring); None when no argument of that type can."""
    if isinstance(t, T.ArrayType):

        def array_token(a: Any) -> Any:
            return id(a) if type(a) is array else _NO

        return array_token
    if isinstance(t, T.ScalarType) and t != T.U64:
        np_type = t.np_dtype.type
        if t.is_float:

            def float_token(a: Any) -> Any:
                ta = type(a)
                if ta is np_type:  # as a Python float (exact): NumPy scalars compare slowly
                    a = float(a)
                elif ta is not float and ta is not int:
                    return _NO
                if a != 0:
                    return a
                # -0.0 == 0.0 (and hashes alike): a zero keys by its sign instead
                return _NEGATIVE_ZERO if copysign(1.0, a) < 0.0 else _ZERO

            return float_token
        py = bool if t.is_bool else int

        def int_token(a: Any) -> Any:
            ta = type(a)
            if ta is np_type:
                return py(a)
            return a if ta is py else _NO

        return int_token
    if isinstance(t, T.VectorType | T.MatrixType):
        dtype, shape = T.elem_type(t).np_dtype, T.value_shape(t)
        classes: set[type] = set()

        def composite_token(a: Any) -> Any:
            ta = type(a)
            if ta not in classes:
                if getattr(ta, "__kdsl_type__", None) != t or not issubclass(ta, np.ndarray):
                    return _NO
                classes.add(ta)
            if a.dtype != dtype or a.shape != shape:
                return _NO
            return a.tobytes()

        return composite_token
    return None


def by_value_indices(arg_types: Sequence[Any]) -> list[int]:
    """The indices of the parameters passed by value that a patchable launch rewrites:
    scalars, vectors, matrices (quaternions, transforms) and handles."""
    return [i for i, t in enumerate(arg_types) if _kind(t) == _BYTES]


def _kind(t: T.Type) -> int | None:
    """How a converted argument of type ``t`` is keyed (None: not keyable)."""
    if isinstance(t, T.ArrayType):
        return _ARRAY
    if isinstance(t, T.ScalarType | T.VectorType | T.MatrixType | T.HandleType):
        return _BYTES
    return None


class _Patch:
    """A patchable launch (``Backend.prepare_patchable``) of one set of arrays, grid and
    stream: its buffers (held weakly), the stream (held) and the thread that owns it
    (the only one that writes and runs it: a write on another thread could reach a
    launch between its write and its run)."""

    __slots__ = ("refs", "run", "stream", "thread", "write")

    def __init__(self, run: Callable[[], None], write: Callable, refs: list, stream: Any):
        self.run = run
        self.write = write
        self.refs = refs
        self.stream = stream
        self.thread = get_ident()

    def alive(self) -> bool:
        """Whether every buffer it was packed with is still alive."""
        return all(ref() is not None for ref in self.refs)


class LaunchReuse:
    """The prepared launches of one plan (kernel, device, backend), by argument key."""

    __slots__ = (
        "array_at", "backend", "bypass", "compiled", "converters", "enabled", "entries",
        "hits", "kinds", "known", "last", "misses", "patches", "same",
        "same_ok", "seen", "split", "tokens", "value_at",
    )  # fmt: skip

    def __init__(
        self, backend: Backend, compiled: CompiledKernel, arg_types: Sequence[Any],
        converters: Sequence[Callable[[Any], Any]] | None = None,
    ) -> None:  # fmt: skip
        """``converters``: per parameter, the plan's converter of an argument object (lets
        ``relaunch`` patch a changed scalar without converting the other arguments)."""
        self.backend = backend
        self.compiled = compiled
        kinds = [_kind(t) for t in arg_types]
        #: False for a signature with a struct (or unknown) parameter: never reused.
        self.enabled = all(k is not None for k in kinds)
        #: The indices of the array parameters, and of the by-value ones (scalars,
        #: vectors, matrices, handles: what a patchable launch writes in place).
        self.array_at = [i for i, k in enumerate(kinds) if k == _ARRAY]
        self.value_at = by_value_indices(arg_types)
        #: The length of a key's array part (``key``): the key of its patchable launch.
        self.split = 2 + 3 * len(self.array_at)
        #: Key -> (run, weak references to its buffers, the stream it runs on).
        self.entries: dict[tuple, tuple[Callable[[], None], list, Any]] = {}
        self.seen: set[tuple] = set()
        #: The entry used last (key, entry), tried before the table.
        self.last: tuple | None = None
        #: Launches that reused a prepared entry (for tests and benchmarks).
        self.hits = 0
        #: Whether ``relaunch`` may serve this signature (arrays and non-id scalars only).
        self.same_ok = self.enabled and all(_same_kind(t) for t in arg_types)
        #: Per parameter, ``_ARRAY`` or ``_BYTES`` (None: not keyable).
        self.kinds = kinds
        self.converters = list(converters) if converters is not None else None
        #: (dims, stream, held arguments, run, the patchable launch of its arrays or their
        #: key, or None) of the launch that used ``last`` or a patchable launch, or None.
        self.same: tuple | None = None
        tokens = [_token(t) for t in arg_types]
        #: Per parameter, how its argument object keys ``known`` (None: no signature key).
        self.tokens: list | None = tokens if self.enabled and None not in tokens else None
        #: Object key (``object_key``) -> (run, weak references to the arrays it names,
        #: the stream it runs on).
        self.known: dict[tuple, tuple[Callable[[], None], list, Any]] = {}
        #: Key of the arrays, grid and stream (``key``'s first ``split`` parts) ->
        #: the ``_Patch`` launching them with any by-value arguments.
        self.patches: dict[tuple, _Patch] = {}
        #: Launches in a row whose key was new (see the module docstring).
        self.misses = 0
        #: Launches left to run without keys (nonzero after a streak of new keys).
        self.bypass = 0

    def relaunch(self, args: Sequence[Any], dims: tuple, stream: Any) -> bool:
        """Run the last entry again if ``args`` are the objects it last ran with, or its
        arrays' patchable launch with ``args``' by-value arguments if only those differ
        (see the module docstring); False (nothing done) otherwise."""
        same = self.same
        if same is None or same[1] is not stream or same[0] != dims:
            return False
        held = same[2]
        if len(held) != len(args):
            return False
        values = False
        for h, a in zip(held, args):
            if h is not a and (type(h) is not _REF or h() is not a):
                if h is _NO:  # a patchable launch's by-value argument
                    values = True
                    continue
                return same[4] is not None and self._repatch(args, same)
        if values:  # the arrays are the held ones: write the by-value arguments
            return self._rewrite(args, same[4])
        self.hits += 1
        self.misses = 0
        same[3]()
        return True

    def _repatch(self, args: Sequence[Any], same: tuple) -> bool:
        """``relaunch`` when an argument of an exact entry's launch is not the one held:
        run the patchable launch of the held arrays (found by their key) with ``args``'
        by-value arguments, if the arrays are the held ones, and remember it instead."""
        if type(same[4]) is _Patch or not self.patches:  # another array, or no patch yet
            return False
        held = same[2]
        for i in self.array_at:  # before hashing the key: another array is the common case
            if held[i]() is not args[i]:
                return False
        patch = self.patches.get(same[4])
        if patch is None or not patch.alive():  # dead: its key's ids may be reused
            return False
        if not self._rewrite(args, patch):
            return False
        new = list(held)
        for i in self.value_at:
            new[i] = _NO
        self.same = (same[0], same[1], tuple(new), patch.run, patch)
        return True

    def _rewrite(self, args: Sequence[Any], patch: _Patch) -> bool:
        """Run ``patch`` with ``args``' by-value arguments (converted, then written), its
        arrays being ``args``' (checked by the caller); False (nothing done) on a thread
        that does not own it.

        A patchable launch's record holds no by-value argument (``_remember``), so every
        launch through it converts and writes them.
        """
        if patch.thread != get_ident():
            return False
        convs = self.converters
        patch.write([convs[i](args[i]) for i in self.value_at])  # a bad value: nothing written
        self.hits += 1
        self.misses = 0
        patch.run()
        return True

    def object_key(
        self, args: Sequence[Any], dims: tuple, stream: Any, extra: Sequence[Any] | None = None
    ) -> tuple | None:
        """The key of ``run_known``'s table for these argument objects, or None when one
        of them cannot key a launch by itself (see the module docstring).

        ``extra``: the key of the parameters after ``args`` (an adjoint launch keys its
        gradient arrays and hidden arguments itself); without it ``args`` must be all of
        them.
        """
        tokens = self.tokens
        if tokens is None or len(args) > len(tokens) or (extra is None and len(args) < len(tokens)):
            return None
        key = [dims, id(stream)]  # the entry holds the stream (``_learn``)
        for tok, a in zip(tokens, args):
            k = tok(a)
            if k is _NO:
                return None
            key.append(k)
        if extra is not None:
            key += extra
        return tuple(key)

    def run_known(self, key: tuple) -> bool:
        """Run the entry learnt under object key ``key``; False (nothing done) when there
        is none or an array it names has died."""
        entry = self.known.get(key)
        if entry is None:
            return False
        run, refs = entry[0], entry[1]
        for ref in refs:
            if ref() is None:  # an array died: its id may now name another one
                del self.known[key]
                return False
        self.hits += 1
        self.misses = 0
        run()
        return True

    def _learn(self, known: tuple | None, run: Any, stream: Any = None) -> None:
        """Keep ``run`` (on ``stream``, held) under object key ``known[0]``, watching the
        arrays in ``known[1]``."""
        if known is None or known[0] is None:
            return
        key, objects = known
        if len(self.known) >= MAX_ENTRIES:
            dead = [k for k, e in self.known.items() if any(r() is None for r in e[1])]
            for k in dead:
                del self.known[k]
            if not dead:
                self.known.clear()
        self.known[key] = (run, [weakref.ref(a) for a in objects if type(a) is array], stream)

    def _remember(
        self, args: Sequence[Any] | None, dims: tuple, stream: Any, run: Any, key: tuple,
        patch: _Patch | None = None,
    ) -> None:  # fmt: skip
        """Keep what ``relaunch`` compares: for an exact entry (``patch`` None) when every
        argument may be compared by identity, for a patchable launch whenever its arrays
        are ``kdsl.array`` objects (its by-value arguments are held as ``_NO``, never the
        same: ``relaunch`` converts and writes them at every launch)."""
        self.same = None
        if args is None or (not self.same_ok if patch is None else self.converters is None):
            return
        held = []
        for a, kind in zip(args, self.kinds):
            ta = type(a)
            if kind == _ARRAY:
                if ta is not array:
                    return
                held.append(weakref.ref(a))
            elif patch is not None:
                held.append(_NO)
            elif ta is float or ta is int or isinstance(a, np.generic):
                held.append(a)
            else:
                return
        if patch is None:  # a later changed scalar finds the patchable launch by this key
            akey = key[: self.split] if self.value_at and self.converters is not None else None
            self.same = (dims, stream, tuple(held), run, akey)
        else:
            self.same = (dims, stream, tuple(held), run, patch)

    def key(self, dims: tuple, converted: Sequence[Any], stream: Any) -> tuple | None:
        """Everything the packed launch depends on, or None when it cannot be keyed: the
        grid, the stream, the arrays, then the bytes of the by-value arguments (its first
        ``split`` parts key the patchable launch)."""
        parts: list[Any] = [dims, id(stream)]  # the entry holds the stream (``_prepare``)
        for i in self.array_at:
            v = converted[i]
            parts += (id(v), v.shape, v.strides)
        for i in self.value_at:
            try:
                parts.append(converted[i].tobytes())
            except AttributeError:  # a backend-specific value: not keyable
                return None
        return tuple(parts)

    def launch(
        self, dims: tuple, converted: Sequence[Any], stream: Any, args: Sequence[Any] | None = None,
        known: tuple | None = None,
    ) -> None:  # fmt: skip
        """Run the launch, reusing its prepared form when its key was prepared before, or
        its arrays' patchable launch when only by-value arguments are new.

        ``args`` (the launch's own argument objects) let the next ``relaunch`` of the
        same objects skip conversion and keying; ``known`` (an ``object_key`` of them, or
        None, and the objects whose arrays it names) lets ``run_known`` serve it.
        """
        if self.bypass:
            self.bypass -= 1
            self.same = None
            self.backend.launch(self.compiled, dims, converted, stream)
            return
        key = self.key(dims, converted, stream) if self.enabled else None
        if key is None:
            self.same = None
            self.backend.launch(self.compiled, dims, converted, stream)
            return
        # The last entry first: comparing two tuples is cheaper than hashing one.
        last = self.last
        entry = last[1] if last is not None and last[0] == key else self.entries.get(key)
        if entry is not None:
            run, refs = entry[0], entry[1]
            for ref in refs:
                if ref() is None:  # a buffer died: its id may now name another one
                    self.entries.pop(key, None)
                    self.last = None
                    break
            else:
                self.hits += 1
                self.misses = 0
                self.last = (key, entry)
                self._remember(args, dims, stream, run, key)
                self._learn(known, run, stream)
                run()
                return
        self.same = None
        if key not in self.seen:
            if len(self.seen) >= MAX_SEEN:
                self.seen.clear()
            self.seen.add(key)
            if self.value_at and self._patch(key, dims, converted, stream, args):
                return
            self.misses += 1
            if self.misses >= MISS_STREAK:  # keys are not paying: skip them for a while
                self.misses = 0
                self.bypass = BYPASS
            self.backend.launch(self.compiled, dims, converted, stream)
            return
        self.misses = 0
        self._prepare(key, dims, converted, stream, args, known)

    def _patch(
        self, key: tuple, dims: tuple, converted: Sequence[Any], stream: Any,
        args: Sequence[Any] | None,
    ) -> bool:  # fmt: skip
        """Run the patchable launch of ``key``'s arrays with the by-value arguments of
        ``converted``, made when those arrays (grid, stream) come a second time; False
        (nothing done) when there is none yet, it died, or another thread owns it."""
        akey = key[: self.split]
        patch = self.patches.get(akey)
        if patch is not None and not patch.alive():  # an id may now name another buffer
            del self.patches[akey]
            patch = None
        if patch is None:
            if akey not in self.seen:
                self.seen.add(akey)
                return False
            patch = self._new_patch(akey, dims, converted, stream)
            if patch is None:
                return False
        elif patch.thread != get_ident():
            return False
        patch.write([converted[i] for i in self.value_at])
        self.hits += 1
        self.misses = 0
        self._remember(args, dims, stream, patch.run, key, patch)
        patch.run()
        return True

    def _new_patch(
        self, akey: tuple, dims: tuple, converted: Sequence[Any], stream: Any
    ) -> _Patch | None:
        """The patchable launch of ``converted``'s arrays, kept under ``akey`` (None when
        the backend cannot make one or a buffer cannot be watched)."""
        refs = self._watch(converted)
        if refs is None:
            return None
        made = self.backend.prepare_patchable(self.compiled, dims, converted, stream,
                                              self.value_at)  # fmt: skip
        if made is None:
            return None
        if len(self.patches) >= MAX_PATCHES:
            dead = [k for k, p in self.patches.items() if not p.alive()]
            for k in dead:
                del self.patches[k]
            if not dead:
                self.patches.clear()
        patch = self.patches[akey] = _Patch(made[0], made[1], refs, stream)
        return patch

    def _prepare(
        self, key: tuple, dims: tuple, converted: Sequence[Any], stream: Any,
        args: Sequence[Any] | None = None, known: tuple | None = None,
    ) -> None:  # fmt: skip
        refs = self._watch(converted)
        run = None
        if refs is not None:
            run = self.backend.prepare_reusable(self.compiled, dims, converted, stream)
        if run is None:  # the backend cannot, or a buffer cannot be watched
            self.backend.launch(self.compiled, dims, converted, stream)
            return
        self.seen.discard(key)
        if len(self.entries) >= MAX_ENTRIES:
            self._drop_dead()
        entry = self.entries[key] = (run, refs, stream)
        self.last = (key, entry)
        self._remember(args, dims, stream, run, key)
        self._learn(known, run, stream)
        run()

    def _drop_dead(self) -> None:
        """Drop the entries with a dead buffer; clear the table when none has one."""
        dead = [k for k, e in self.entries.items() if any(r() is None for r in e[1])]
        for k in dead:
            del self.entries[k]
        if not dead:
            self.entries.clear()
        self.last = None
        self.same = None

    def _watch(self, converted: Sequence[Any]) -> list | None:
        """Weak references to the entry's buffers (None: one is not weak-referenceable)."""
        try:
            return [weakref.ref(converted[i]) for i in self.array_at]
        except TypeError:
            return None

    def clear(self) -> None:
        """Forget every prepared launch."""
        self.entries.clear()
        self.seen.clear()
        self.known.clear()
        self.patches.clear()
        self.last = None
        self.same = None
