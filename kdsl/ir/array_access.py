"""Which array parameters a function reads and which it writes.

``array_param_access(module, name)`` follows each array parameter of function ``name``
through what derives an array from it (``kd.array_view``) and into the functions it is
passed to (``func.call``), and records a read for ``kd.load`` and a write for
``kd.store``, ``kd.atomic_rmw`` and ``kd.atomic_cas``, as Warp's code generator marks
its kernel arguments for ``warp.config.verify_autograd_array_access`` (an atomic counts
as a write only, as in Warp). Arrays inside struct parameters are not followed (Warp
checks plain array arguments only). It never changes the IR.
"""

from __future__ import annotations

from dataclasses import dataclass

from kdsl.ir.core import Module, OpResult, Value
from kdsl.ir.types import ArrayType

_WRITES = frozenset({"kd.store", "kd.atomic_rmw", "kd.atomic_cas"})


@dataclass(frozen=True)
class ParamAccess:
    """How a function uses one parameter: ``read`` (loads from it), ``write`` (stores or
    atomics into it). Non-array parameters are neither."""

    read: bool = False
    write: bool = False


def array_param_access(module: Module, name: str) -> list[ParamAccess]:
    """One ``ParamAccess`` per parameter of function ``name`` in ``module``."""
    memo: dict[str, list[ParamAccess]] = {}
    return _function_access(module, name, memo, set())


def _function_access(
    module: Module, name: str, memo: dict[str, list[ParamAccess]], active: set[str]
) -> list[ParamAccess]:
    if name in memo:
        return memo[name]
    params = module.get_func(name).regions[0].block.args
    if name in active:  # recursion: what the outer visit finds is what counts
        return [ParamAccess()] * len(params)
    active.add(name)
    out = [
        _value_access(module, p, memo, active) if isinstance(p.type, ArrayType) else ParamAccess()
        for p in params
    ]
    active.discard(name)
    memo[name] = out
    return out


def _value_access(
    module: Module, value: Value, memo: dict[str, list[ParamAccess]], active: set[str]
) -> ParamAccess:
    read = write = False
    pending, seen = [value], set()
    while pending:
        v = pending.pop()
        if id(v) in seen:
            continue
        seen.add(id(v))
        for op, index in v.uses:
            if op.name == "kd.load":
                read = True
            elif op.name in _WRITES and index == op.opdef.array_operand:
                write = True
            elif op.name == "kd.array_view" and index == 0:
                pending.append(op.results[0])
            elif op.name == "func.call":
                callee = _function_access(module, op.attrs["callee"], memo, active)
                if index < len(callee):
                    read |= callee[index].read
                    write |= callee[index].write
    return ParamAccess(read, write)


def writes_only_params(module: Module, name: str) -> bool:
    """True when every array write of function ``name`` (and of the functions it calls)
    lands in an array parameter of ``name``: each store or atomic's array derives
    (through ``kd.array_view``) from a parameter of the function it is in, and each
    array a call passes where the callee writes derives from a caller's parameter.

    False when some write goes through an array the parameters do not cover (a field
    of a struct parameter, ``kd.array_from_ptr``, an object record): then the arrays a
    function only reads may still be written through another name.
    """
    return _writes_only_params(module, name, {}, set())


def _writes_only_params(module: Module, name: str, memo: dict[str, bool], active: set[str]) -> bool:
    if name in memo:
        return memo[name]
    if name in active:  # recursion: the outer visit checks every op
        return True
    active.add(name)
    func = module.get_func(name)
    params = set(func.regions[0].block.args)
    ok = True
    for op in func.walk():
        if op.name in _WRITES:
            ok = _param_root(op.operands[op.opdef.array_operand], params)
        elif op.name == "func.call":
            callee = op.attrs["callee"]
            written = _function_access(module, callee, {}, set())
            ok = _writes_only_params(module, callee, memo, active) and all(
                _param_root(v, params) for v, acc in zip(op.operands, written) if acc.write
            )
        if not ok:
            break
    active.discard(name)
    memo[name] = ok
    return ok


def _param_root(value: Value, params: set[Value]) -> bool:
    """True when ``value`` is one of ``params`` or a view (``kd.array_view``) of one."""
    while value not in params:
        if not isinstance(value, OpResult) or value.op.name != "kd.array_view":
            return False
        value = value.op.operands[0]
    return True
