"""``kdsl.map``: Warp's ``wp.map`` -- apply a function elementwise over arrays in a kernel.

``map(func, *inputs, out=None, return_kernel=False, block_dim=None, device=None)``:

- ``func`` is a ``@kdsl.func``, a kernel builtin (``kdsl.clamp``, ``kdsl.transform_point``),
  or a plain Python function or lambda written in the kernel language (its source is
  compiled as a ``@kdsl.func`` whose unannotated parameters are ``Any``);
- ``inputs`` are kdsl arrays or indexed arrays (at least one) and plain values
  (numbers, vectors, transforms...), passed to every call. Array shapes broadcast as
  in NumPy; the launch covers the broadcast shape;
- outputs are created from the function's result types (a tuple result gives one
  array per element), on the inputs' device, with ``requires_grad`` when an input
  array requires it; or written into ``out`` (an array, or a list for tuple results),
  which must have the broadcast shape and the result dtype (``out`` may be an input:
  in-place maps work).

The generated kernel is cached per function, input types and broadcast pattern, so
repeated maps compile once. ``return_kernel=True`` returns that kernel without
launching it (its parameters are the inputs, then the outputs).
"""

from __future__ import annotations

import ast
import inspect
import itertools
import linecache
import textwrap
import types
from typing import Any

import numpy as np

from kdsl.errors import KdslTypeError, KdslValueError
from kdsl.frontend.api import tid
from kdsl.frontend.builtins_base import Builtin
from kdsl.frontend.compiler import FunctionCompiler, ModuleCompiler
from kdsl.frontend.kernel import CompileTarget, Function, func, kernel
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device
from kdsl.runtime.indexed import indexedarray
from kdsl.runtime.launch import launch
from kdsl.types import class_of, dtype_from_numpy, type_of

_counter = itertools.count()
#: Generated kernels by (function, input signature, broadcast pattern, out types).
_KERNELS: dict[tuple, Any] = {}
#: Python functions and lambdas compiled as @func, by the function object.
_WRAPPED: dict[Any, Function] = {}


def _register_source(tag: str, source: str) -> str:
    """Put generated ``source`` in linecache under a unique file name (kept: kernels
    re-read their source when they recompile)."""
    filename = f"<kdsl map {tag} {next(_counter)}>"
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    return filename


def _lambda_node(fn: types.FunctionType) -> ast.Lambda:
    try:
        src = textwrap.dedent(inspect.getsource(fn))
    except (OSError, TypeError):
        raise KdslTypeError("map(): cannot read the source of the lambda") from None
    names = list(fn.__code__.co_varnames[: fn.__code__.co_argcount])
    for text in (src, f"({src.strip().rstrip(',')})"):
        try:
            tree = ast.parse(text)
        except SyntaxError:
            continue
        found = [n for n in ast.walk(tree) if isinstance(n, ast.Lambda)
                 and [a.arg for a in n.args.args] == names]  # fmt: skip
        if len(found) == 1:
            return found[0]
        if found:
            raise KdslTypeError("map(): several lambdas with these parameters on one line; "
                                "define the function with def")  # fmt: skip
    raise KdslTypeError("map(): cannot find the lambda's source; define it with def")


def _as_function(fn: Any) -> Any:
    """``fn`` as something a kernel can call: a @func or builtin as is; a Python function
    or lambda compiled as a @func (unannotated parameters become ``Any``)."""
    if isinstance(fn, Function | Builtin):
        return fn
    if not isinstance(fn, types.FunctionType):
        raise KdslTypeError(f"map() takes a @kdsl.func, a kdsl builtin or a Python function, "
                            f"not {type(fn).__name__}")  # fmt: skip
    hit = _WRAPPED.get(fn)
    if hit is not None:
        return hit
    if fn.__name__ == "<lambda>":
        node = _lambda_node(fn)
        params = [a.arg for a in node.args.args]
        body = f"    return {ast.unparse(node.body)}\n"
    else:
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
        except (OSError, TypeError, SyntaxError):
            raise KdslTypeError(f"map(): cannot read the source of {fn.__name__}()") from None
        fdef = tree.body[0]
        if not isinstance(fdef, ast.FunctionDef):
            raise KdslTypeError(f"map(): {fn.__name__} is not a plain function")
        fdef.decorator_list = []
        params = [a.arg for a in fdef.args.args]
        body = textwrap.indent("\n".join(ast.unparse(s) for s in fdef.body), "    ") + "\n"
    anns = fn.__annotations__
    name = f"map_fn_{next(_counter)}"
    sig = ", ".join(f"{p}: __ann_{p}" for p in params)
    source = f"def {name}({sig}):\n{body}"
    scope = dict(fn.__globals__)
    if fn.__closure__:
        scope.update(zip(fn.__code__.co_freevars, (c.cell_contents for c in fn.__closure__)))
    scope.update({f"__ann_{p}": anns.get(p, Any) for p in params})
    exec(compile(source, _register_source("function", source), "exec"), scope)
    out = _WRAPPED[fn] = func(scope[name])
    return out


def _value_annotation(v: Any) -> Any:
    if isinstance(v, bool | np.bool_):
        return type_of(bool)
    if isinstance(v, int):
        return type_of(int)
    if isinstance(v, float):
        return type_of(float)
    if isinstance(v, np.generic):
        return type_of(dtype_from_numpy(v.dtype))
    t = getattr(type(v), "__kdsl_type__", None)
    if t is None:
        raise KdslTypeError(f"map(): cannot pass {type(v).__name__} to a kernel; inputs are "
                            f"kdsl arrays and kernel values (numbers, vectors, ...)")  # fmt: skip
    return type_of(type(v))


class _Probe(CompileTarget):
    def __init__(self, fn: Any) -> None:
        self.fn = fn
        self.name = fn.__name__

    def inout_params(self) -> tuple[int, ...]:
        return ()


def _result_types(fn: Any, elem_types: list[Any]) -> list[Any]:
    """The types ``fn`` returns for arguments of ``elem_types`` (compiled by the frontend)."""
    params = [f"a{k}" for k in range(len(elem_types))]
    name = f"map_probe_{next(_counter)}"
    source = f"def {name}({', '.join(params)}):\n    return f({', '.join(params)})\n"
    scope: dict[str, Any] = {"f": fn, "__name__": "kdsl.utils.map"}
    exec(compile(source, _register_source("probe", source), "exec"), scope)
    unit = ModuleCompiler(name)
    FunctionCompiler(unit, _Probe(scope[name]), "func").compile(name, elem_types)
    res = list(unit.module.get_func(name).attrs["res_types"])
    if not res:
        raise KdslTypeError(f"map(): {getattr(fn, 'name', fn)} returns nothing; a mapped "
                            f"function must return a value")  # fmt: skip
    return res


def _index(ndim_out: int, shape: tuple[int, ...], out_shape: tuple[int, ...]) -> str:
    lead = ndim_out - len(shape)
    idx = ["0" if shape[d] == 1 and out_shape[lead + d] != 1 else f"i{lead + d}"
           for d in range(len(shape))]  # fmt: skip
    return ", ".join(idx)


def _build_kernel(fn: Any, inputs: list[Any], anns: list[Any], out_types: list[Any],
                  shape: tuple[int, ...]) -> Any:  # fmt: skip
    nd = len(shape)
    params = [f"x{k}" for k in range(len(inputs))]
    outs = [f"o{k}" for k in range(len(out_types))]
    tid_vars = ", ".join(f"i{d}" for d in range(nd))
    args = [f"x{k}[{_index(nd, tuple(x.shape), shape)}]" if isinstance(x, array | indexedarray)
            else f"x{k}" for k, x in enumerate(inputs)]  # fmt: skip
    results = ", ".join(f"r{k}" for k in range(len(outs)))
    stores = "".join(f"    o{k}[{tid_vars}] = r{k}\n" for k in range(len(outs)))
    sig = ", ".join(f"{p}: __ann_{p}" for p in params + outs)
    name = f"map_kernel_{next(_counter)}"
    source = (f"def {name}({sig}):\n    {tid_vars} = tid()\n"
              f"    {results} = f({', '.join(args)})\n{stores}")  # fmt: skip
    scope: dict[str, Any] = {"f": fn, "tid": tid, "__name__": "kdsl.utils.map"}
    scope.update({f"__ann_{p}": a for p, a in zip(params, anns)})
    scope.update({f"__ann_{o}": array(dtype=class_of(t), ndim=nd)
                  for o, t in zip(outs, out_types)})  # fmt: skip
    exec(compile(source, _register_source("kernel", source), "exec"), scope)
    return kernel(scope[name])


def _outputs(out: Any, out_types: list[Any], shape: tuple[int, ...], device: Any,
             grad: bool) -> list[array]:  # fmt: skip
    from kdsl.runtime.alloc import empty

    if out is None:
        return [empty(shape, dtype=class_of(t), device=device, requires_grad=grad)
                for t in out_types]  # fmt: skip
    outs = list(out) if isinstance(out, list | tuple) else [out]
    if len(outs) != len(out_types):
        raise KdslValueError(f"map(): the function returns {len(out_types)} values but out "
                             f"holds {len(outs)} arrays")  # fmt: skip
    for k, (o, t) in enumerate(zip(outs, out_types)):
        if not isinstance(o, array):
            raise KdslTypeError(f"map(): out[{k}] must be a kdsl array, not {type(o).__name__}")
        if tuple(o.shape) != shape:
            raise KdslValueError(f"map(): out[{k}] has shape {tuple(o.shape)}; the inputs "
                                 f"broadcast to {shape}")  # fmt: skip
        if o.__kdsl_type__.dtype != t:
            raise KdslTypeError(f"map(): out[{k}] holds {o.__kdsl_type__.dtype}; the function "
                                f"returns {t}")  # fmt: skip
        if o.device != device:
            raise KdslValueError(f"map(): out[{k}] is on '{o.device}', the inputs on '{device}'")
    return outs


def map(  # noqa: A001 - Warp's name
    func: Any,
    *inputs: Any,
    out: Any = None,
    return_kernel: bool = False,
    block_dim: int | None = None,
    device: Any = None,
) -> Any:
    """Apply ``func`` elementwise over ``inputs`` in a kernel (see the module docstring).

    Returns the output array (a list of them for tuple results), or the kernel when
    ``return_kernel`` is True. ``block_dim`` is accepted for Warp's signature (kdsl
    picks the CUDA block size per launch).
    """
    fn = _as_function(func)
    arrays = [x for x in inputs if isinstance(x, array | indexedarray)]
    if not arrays:
        raise KdslTypeError("map(): at least one input must be a kdsl array")
    devices = {get_device(x.device) for x in arrays}
    if len(devices) > 1:
        raise KdslValueError(f"map(): the input arrays live on different devices: "
                             f"{sorted(str(d) for d in devices)}")  # fmt: skip
    dev = devices.pop()
    if device is not None and get_device(device) != dev:
        raise KdslValueError(f"map(): device='{get_device(device)}' but the inputs are on '{dev}'")
    try:
        shape = tuple(int(n) for n in np.broadcast_shapes(*(tuple(x.shape) for x in arrays)))
    except ValueError:
        raise KdslValueError(f"map(): the input shapes {[tuple(x.shape) for x in arrays]} do "
                             f"not broadcast together") from None  # fmt: skip
    if not 1 <= len(shape) <= 4:
        raise KdslValueError(f"map(): the broadcast shape {shape} must have 1 to 4 dimensions")
    anns = [x.__kdsl_type__ if isinstance(x, array | indexedarray) else _value_annotation(x)
            for x in inputs]  # fmt: skip
    elem = [a.dtype if isinstance(x, array) else
            (type_of(x.dtype) if isinstance(x, indexedarray) else a)
            for x, a in zip(inputs, anns)]  # fmt: skip
    pattern = tuple(_index(len(shape), tuple(x.shape), shape)
                    if isinstance(x, array | indexedarray) else None for x in inputs)  # fmt: skip
    key = (fn, tuple(anns), pattern, len(shape))
    entry = _KERNELS.get(key)
    if entry is None:
        out_types = _result_types(fn, elem)
        entry = _KERNELS[key] = (_build_kernel(fn, list(inputs), anns, out_types, shape),
                                 out_types)  # fmt: skip
    k, out_types = entry
    if return_kernel:
        return k
    grad = any(getattr(x, "requires_grad", False) for x in arrays)
    outs = _outputs(out, out_types, shape, dev, grad)
    launch(k, dim=shape, inputs=[*inputs, *outs], device=dev)
    return outs[0] if len(outs) == 1 else outs


__all__ = ["map"]
