"""Python scope: kernel builtins, standard-library functions and operators on kdsl values,
evaluated from plain Python with the kernel's own semantics.

``kdsl.sin(0.5)``, ``kdsl.dot(a, b)``, ``kdsl.quat_rotate(q, v)`` and ``v * 2.0`` on a
``kdsl.vec3`` all come here (through the hook ``kdsl.types.register_python_scope``). No
builtin has a second, NumPy version: a call is compiled once per callee and argument
types into a one-line IR function whose body is the kernel-scope lowering of that very
call (``def f(a0, a1): return dot(a0, a1)``, compiled by the frontend), optimized by the
``interp`` backend's pipeline through the compile driver, and run by the ``interp``
program: the catalog's interpreter rules give the result, bit for bit what a kernel gives
on ``interp``. Later calls with the same types cost a dict lookup and one interpreted call.

Arguments are typed as in a kernel:

- kdsl vectors, matrices, quaternions and transforms (``kdsl.types.Composite``), NumPy
  scalars (``np.float32(1)``, ``kdsl.float64(2)``) and Python bools are typed values;
- Python ints and floats are weak literals, typed by the call as a kernel types a literal
  (``kdsl.sin(0.5)`` is f32, ``kdsl.mul(v3d, 2.0)`` scales a ``vec3d``). The function is
  compiled with a placeholder for each literal: where the lowering turns it into a
  constant of type ``T``, the placeholder becomes a parameter of type ``T`` instead,
  converted from the Python number exactly as the constant would be. Where a lowering
  reads a literal's value at compile time (``identity(n=3)``), the compiled function
  depends on that value and is cached per value (a bounded cache);
- anything else hashable (a dtype such as ``kdsl.float64``, a type) is a compile-time
  object, as a global name is in a kernel.

Results come back as Python-scope values: NumPy scalars of the result type and
``kdsl.types`` composite classes. In-out parameters (``randf(state)``) are passed by
value: a Python int cannot be updated in place, so the caller's state does not advance.
"""

from __future__ import annotations

import linecache
import threading
from collections import OrderedDict
from typing import Any

import numpy as np

from kdsl.backends.registry import get_backend
from kdsl.compiler.driver import compile_kernel
from kdsl.errors import KdslError, KdslTypeError
from kdsl.frontend.builtins_base import Builtin
from kdsl.frontend.compiler import FunctionCompiler, ModuleCompiler
from kdsl.frontend.kernel import CompileTarget
from kdsl.frontend.values import literal_fits
from kdsl.ir import verify_module
from kdsl.ir.builder import normalize_constant
from kdsl.ir.semantics import np_value
from kdsl.ir.types import BOOL, ScalarType, Type, scalar_from_numpy
from kdsl.passes import run_pipeline
from kdsl.types import Composite, class_of

#: The file name the generated callers carry (and that errors must not point at).
SCOPE_FILE = "<kdsl python scope>"

#: Operator spellings the hook accepts, as Python source over the parameters.
_OPERATORS = {
    "add": "{0} + {1}", "sub": "{0} - {1}", "mul": "{0} * {1}", "truediv": "{0} / {1}",
    "floordiv": "{0} // {1}", "mod": "{0} % {1}", "matmul": "{0} @ {1}", "neg": "-{0}",
    "pos": "+{0}",
}  # fmt: skip

#: How many value-dependent compiled calls are kept (least recently used go first).
VALUE_CACHE_SIZE = 256

_cache: dict[tuple, _Compiled] = {}
_value_cache: OrderedDict[tuple, _Compiled] = OrderedDict()
#: Signatures whose compiled function depends on a literal's value.
_value_dependent: set[tuple] = set()
_lock = threading.Lock()
_counter = iter(range(1, 1 << 62))


def evaluate(what: Any, args: tuple, kwargs: dict[str, Any] | None = None) -> Any:
    """``what(*args, **kwargs)`` in Python scope with kernel semantics.

    ``what`` is a kernel ``Builtin``, a ``@kdsl.func`` ``Function`` or an operator name
    of ``_OPERATORS`` (``"mul"`` for ``a * b``). Raises a ``KdslError`` for arguments
    the kernel would refuse.
    """
    kwargs = kwargs or {}
    kinds, values = [], []
    for k, a in enumerate((*args, *kwargs.values())):
        kind, value = _classify(what, k, a)
        kinds.append(kind)
        values.append(value)
    key = (what, tuple(kinds), tuple(kwargs))
    compiled = _cache.get(key)
    if compiled is None:
        compiled = _lookup_slow(key, what, args, kwargs, kinds, values)
    return compiled.run(values)


class _Compiled:
    """One compiled call: its program and how to feed and read it."""

    def __init__(self, program: Any, symbol: str, typed: list[int],
                 weak: list[tuple[int, ScalarType]], res_types: list[Type]) -> None:  # fmt: skip
        # The interp backend loads only when Python scope is first used (``import kdsl``
        # imports no backend).
        from kdsl.backends.interp.program import ThreadContext

        self.context = ThreadContext
        self.program = program
        self.symbol = symbol
        self.fn = program.function(symbol)
        self.typed = typed
        self.weak = weak
        self.res = [_result_converter(t) for t in res_types]

    def run(self, values: list[Any]) -> Any:
        args = [values[k] for k in self.typed]
        args += [np_value(normalize_constant(values[k], t), t) for k, t in self.weak]
        ctx = self.context(self.program, self.fn, "python scope")
        try:
            with np.errstate(all="ignore"):
                out = ctx.call(self.symbol, args)
        except KdslError as e:
            raise _scrubbed(e) from None
        if not out:
            return None
        if len(out) == 1:
            return self.res[0](out[0])
        return tuple(conv(v) for conv, v in zip(self.res, out))


def _lookup_slow(key, what, args, kwargs, kinds, values) -> _Compiled:
    with _lock:
        if key in _value_dependent:
            vkey = (key, tuple(_literal_key(v) for kind, v in zip(kinds, values)
                               if kind[0] == "weak"))  # fmt: skip
            hit = _value_cache.get(vkey)
            if hit is not None:
                _value_cache.move_to_end(vkey)
                return hit
            compiled, _ = _build(what, args, kwargs, kinds, values)
            _value_cache[vkey] = compiled
            if len(_value_cache) > VALUE_CACHE_SIZE:
                _value_cache.popitem(last=False)
            return compiled
        compiled, parametric = _build(what, args, kwargs, kinds, values)
        if parametric:
            _cache[key] = compiled
        else:
            _value_dependent.add(key)
        return compiled


def _literal_key(x: Any) -> Any:
    # 0.0 and -0.0 (and NaNs) must not share an entry.
    return (type(x), x.hex()) if isinstance(x, float) else (type(x), x)


def _classify(what: Any, k: int, a: Any) -> tuple[tuple, Any]:
    """``(kind, value)`` of one argument: its part of the cache key and what is passed."""
    if isinstance(a, np.generic) and a.dtype.kind in "biuf":
        try:
            return ("typed", scalar_from_numpy(a.dtype)), a
        except (KeyError, TypeError):
            pass
    if isinstance(a, bool):
        return ("typed", BOOL), np.bool_(a)
    if isinstance(a, float):
        return ("weak", float), float(a)
    if isinstance(a, int):
        if not -(2**63) <= a < 2**64:
            raise KdslTypeError(f"{_name(what)}: the integer {a} does not fit in 64 bits")
        return ("weak", int), int(a)
    if isinstance(a, Composite):
        return ("typed", type(a).__kdsl_type__), a.view(np.ndarray)
    if isinstance(a, np.ndarray | list | tuple | dict | set | np.generic) or a is None:
        raise KdslTypeError(
            f"{_name(what)}: argument {k + 1} is {_describe(a)}; Python scope takes kdsl "
            "values (kdsl.vec3(...), kdsl.mat33(...), kdsl.quat(...), kdsl.float32(...)), "
            "Python numbers and bools"
        )
    try:
        hash(a)
    except TypeError:
        raise KdslTypeError(f"{_name(what)}: argument {k + 1} is {_describe(a)}, which "
                            "is not a kdsl value") from None  # fmt: skip
    return ("static", a), a


def _describe(a: Any) -> str:
    if isinstance(a, np.ndarray):
        return f"a NumPy array of shape {a.shape} and dtype {a.dtype}"
    if isinstance(a, np.generic):
        return f"a NumPy {a.dtype} scalar"
    if a is None:
        return "None"
    return f"a Python {type(a).__name__}"


def _name(what: Any) -> str:
    if isinstance(what, str):
        return f"the operator {_OPERATORS[what].format('a', 'b').strip()}"
    return f"kdsl.{what.name}()"


# --- building a caller -----------------------------------------------------------------


class _Placeholder:
    """Mixed into ``float``/``int``: a weak literal whose value the caller supplies.

    Reading its value at compile time (comparing it, converting it, doing arithmetic on
    it, printing it) marks it ``inspected``: the compiled function then depends on it.
    """

    index: int
    inspected: bool
    consumed: bool


def _tracking(base: type, name: str):
    method = getattr(base, name)

    def wrapper(self, *args):
        self.inspected = True
        return method(self, *args)

    wrapper.__name__ = name
    return wrapper


_VALUE_DUNDERS = (
    "__eq__", "__ne__", "__lt__", "__le__", "__gt__", "__ge__", "__bool__", "__hash__",
    "__float__", "__int__", "__index__", "__trunc__", "__floor__", "__ceil__", "__round__",
    "__neg__", "__pos__", "__abs__", "__invert__", "__add__", "__radd__", "__sub__",
    "__rsub__", "__mul__", "__rmul__", "__truediv__", "__rtruediv__", "__floordiv__",
    "__rfloordiv__", "__mod__", "__rmod__", "__pow__", "__rpow__", "__divmod__",
    "__lshift__", "__rshift__", "__and__", "__or__", "__xor__", "__format__", "__str__",
    "__repr__", "__getnewargs__", "as_integer_ratio", "hex", "is_integer",
)  # fmt: skip


def _placeholder_class(base: type) -> type:
    ns = {n: _tracking(base, n) for n in _VALUE_DUNDERS if hasattr(base, n)}
    return type(f"weak_{base.__name__}", (base, _Placeholder), ns)


_PLACEHOLDERS = {float: _placeholder_class(float), int: _placeholder_class(int)}


class _Caller(CompileTarget):
    """The generated one-line function, as the frontend's compile target."""

    def __init__(self, fn: Any) -> None:
        self.fn = fn
        self.name = fn.__name__

    def inout_params(self) -> tuple[int, ...]:
        return ()


class _ScopeCompiler(FunctionCompiler):
    """The caller's compiler: a placeholder literal typed ``T`` becomes a parameter."""

    def __init__(self, unit: ModuleCompiler, target: _Caller, symbol: str) -> None:
        super().__init__(unit, target, "func")
        self.symbol = symbol
        #: ``(argument index, type)`` of each parameter added for a literal, in order.
        self.weak_params: list[tuple[int, ScalarType]] = []

    def const(self, x: Any, t: Type, node: Any = None) -> Any:
        if not isinstance(x, _Placeholder) or not isinstance(t, ScalarType):
            return super().const(x, t, node)
        why = literal_fits(x, t)
        if why:
            raise self.error(KdslTypeError, why, node)
        x.consumed = True
        body = self.unit.module.get_func(self.symbol).regions[0].block
        self.weak_params.append((x.index, t))
        return body.add_arg(t, f"lit{x.index}")


def _build(what, args, kwargs, kinds, values) -> tuple[_Compiled, bool]:
    """Compile the call; also says whether it holds for every value of its literals."""
    n = next(_counter)
    symbol = f"python_scope_{n}"
    names = [f"a{k}" for k in range(len(kinds))]
    params = [nm for nm, kind in zip(names, kinds) if kind[0] == "typed"]
    call_args = names[: len(args)]
    call_kw = [f"{kw}={nm}" for kw, nm in zip(kwargs, names[len(args) :])]
    if isinstance(what, str):
        body = _OPERATORS[what].format(*call_args)
    else:
        body = f"f({', '.join(call_args + call_kw)})"
    source = f"def {symbol}({', '.join(params)}):\n    return {body}\n"
    filename = f"{SCOPE_FILE[:-1]} {n}>"
    scope: dict[str, Any] = {"f": what, "__name__": "kdsl.python_scope"}
    placeholders = []
    for k, (nm, kind, v) in enumerate(zip(names, kinds, values)):
        if kind[0] == "weak":
            ph = _PLACEHOLDERS[kind[1]](v)
            ph.index, ph.inspected, ph.consumed = k, False, False
            placeholders.append(ph)
            scope[nm] = ph
        elif kind[0] == "static":
            scope[nm] = v
    exec(compile(source, filename, "exec"), scope)
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    try:
        unit = ModuleCompiler(symbol)
        fc = _ScopeCompiler(unit, _Caller(scope[symbol]), symbol)
        try:
            fc.compile(symbol, [kind[1] for kind in kinds if kind[0] == "typed"])
        except RecursionError:
            raise KdslTypeError(f"{_name(what)} could not be compiled (too deep)") from None
        verify_module(unit.module)
        backend = get_backend("interp")
        # The interp pipeline, but the caller (a function no kernel calls) is kept.
        run_pipeline(unit.module, _keep_functions(backend.pipeline))
        compiled = compile_kernel(backend, unit.module, symbol, {"optimize": False})
    except KdslError as e:
        raise _scrubbed(e, what) from None
    finally:
        linecache.cache.pop(filename, None)
    typed = [k for k, kind in enumerate(kinds) if kind[0] == "typed"]
    res_types = compiled.module.get_func(symbol).attrs["res_types"]
    parametric = all(p.consumed and not p.inspected for p in placeholders)
    return _Compiled(compiled.payload, symbol, typed, fc.weak_params, res_types), parametric


def _keep_functions(pipeline: str) -> str:
    return ",".join("inline{drop_unused=false}" if p.strip() == "inline" else p
                    for p in pipeline.split(","))  # fmt: skip


def _scrubbed(e: KdslError, what: Any = None) -> KdslError:
    """``e`` without the generated caller's location (the user's call is in the traceback),
    its message naming the callee."""
    if e.loc is not None and str(e.loc.file).startswith(SCOPE_FILE[:-1]):
        e.loc = None
        e.func = None
        if what is not None and not isinstance(what, str):
            name = _name(what)
            if not e.message.startswith(name.removeprefix("kdsl.").split("(")[0]):
                e.message = f"{name}: {e.message}"
                e.args = (e.message,)
    return e.with_traceback(None)


def _result_converter(t: Type):
    if isinstance(t, ScalarType):
        scalar = t.np_dtype.type
        return lambda v: v if type(v) is scalar else scalar(v)
    try:
        cls = class_of(t)
    except TypeError:
        return lambda v: v
    dtype = t.elem.np_dtype if hasattr(t, "elem") else None
    return lambda v: np.array(v, dtype=dtype).view(cls)


def _check_callable(what: Any) -> None:
    if isinstance(what, Builtin) and what.group == "memory":
        raise KdslError(
            f"kdsl.{what.name}() reads or writes arrays or the thread index: it is a kernel "
            "builtin only, with no meaning in Python scope"
        )


def call(what: Any, args: tuple, kwargs: dict[str, Any]) -> Any:
    """The hook ``kdsl.types.register_python_scope`` receives: checks, then evaluates."""
    if not isinstance(what, str):
        _check_callable(what)
    return evaluate(what, args, kwargs)


__all__ = ["SCOPE_FILE", "VALUE_CACHE_SIZE", "call", "evaluate"]
