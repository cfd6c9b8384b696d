"""The ``func`` dialect: functions, calls and returns.

``func.func`` is a module-level op holding one region whose entry block arguments
are the parameters. Attributes: ``sym_name`` (its name), ``kind`` ("kernel" or
"func") and ``res_types`` (the result types, printed after ``->``). A kernel
returns nothing. ``func.call`` refers to a function of the same module by name.
"""

from __future__ import annotations

from kdsl.ir.catalog import CATALOG


def func_result_types(func) -> list:
    return list(func.attrs.get("res_types", []))


def _func_verify(op) -> None:
    if op.attrs.get("kind") not in ("kernel", "func"):
        raise TypeError(f"func.func kind must be 'kernel' or 'func', not {op.attrs.get('kind')!r}")
    if op.attrs["kind"] == "kernel" and func_result_types(op):
        raise TypeError("a kernel returns no values")
    term = op.regions[0].block.terminator
    if term is None or term.name != "func.return":
        raise TypeError(f"function {op.attrs['sym_name']} must end with func.return")


def _return_verify(op) -> None:
    func = op.parent_op()
    if func is None or func.name != "func.func":
        raise TypeError("func.return must end the body of a func.func")
    got = [v.type for v in op.operands]
    want = func_result_types(func)
    if got != want:
        raise TypeError(
            f"function {func.attrs['sym_name']} returns ({', '.join(map(str, want))}) "
            f"but this returns ({', '.join(map(str, got))})"
        )


def _call_interp(ctx, op, *args):
    out = ctx.call(op.attrs["callee"], args)
    if len(op.results) == 1:
        return out[0]
    return tuple(out) if op.results else None


FUNC = CATALOG.define(
    "func.func", "A function or kernel (see the module docstring).",
    verifier=_func_verify, num_regions=1, required_attrs=("sym_name", "kind"), group="functions",
    example='func.func @f(%x: f32) -> (f32) {kind = "func"} {\n  func.return %x\n}',
)  # fmt: skip
CALL = CATALOG.define(
    "func.call", "Call a function of the module by name; gives its results.",
    interp=_call_interp, required_attrs=("callee",), group="functions",
    example='%1 = func.call %0 {callee = "f"} : f32',
)  # fmt: skip
RETURN = CATALOG.define_terminator(
    "func.return", "Return from a function with its result values (none for a kernel).",
    verifier=_return_verify, example="func.return %0", group="functions",
)  # fmt: skip
