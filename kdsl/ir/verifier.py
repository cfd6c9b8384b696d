"""The IR verifier: structural invariants, dominance, and each op's own rules.

Checks, for every op: its region count and required attributes; that every operand
is defined before the op in the same block or an enclosing one (structured SSA
dominance); that regions end with a terminator and terminators end blocks; that
result types agree with the op's type rule; and the op's own verifier. Failures
raise ``KdslVerifyError`` whose message shows the op's text and location.
"""

from __future__ import annotations

from kdsl.errors import KdslVerifyError
from kdsl.ir.core import Block, Module, Operation, Value


def _fail(op: Operation, message: str) -> KdslVerifyError:
    from kdsl.ir.printer import print_op

    text = print_op(op).splitlines()[0] if op.name != "func.func" else op.attrs.get("sym_name")
    return KdslVerifyError(f"{message}\n  in: {text}", op.loc)


def verify_op(op: Operation, visible: set[int]) -> None:
    """Verify ``op`` (recursively); ``visible`` holds ids of values in scope."""
    opdef = op.opdef
    if len(op.regions) != opdef.num_regions:
        raise _fail(op, f"{op.name} needs {opdef.num_regions} regions, has {len(op.regions)}")
    for key in opdef.required_attrs:
        if key not in op.attrs:
            raise _fail(op, f"{op.name} needs attribute {key!r}")
    for i, v in enumerate(op.operands):
        if id(v) not in visible:
            raise _fail(op, f"operand {i} of {op.name} is not defined before its use")
        if (op, i) not in v.uses:
            raise _fail(op, f"operand {i} of {op.name} is missing from its use-list")
    if opdef.type_rule is not None:
        try:
            want = list(opdef.type_rule([v.type for v in op.operands], op.attrs))
        except TypeError as e:
            raise _fail(op, str(e)) from None
        got = [r.type for r in op.results]
        if want != got:
            raise _fail(op, f"{op.name} should give ({_fmt(want)}), not ({_fmt(got)})")
    for region in op.regions:
        if len(region.blocks) != 1:
            raise _fail(op, "a kdsl region holds exactly one block")
        if region.parent is not op:
            raise _fail(op, "region parent link is broken")
        verify_block(region.block, set(visible), op)
    if opdef.verifier is not None:
        try:
            opdef.verifier(op)
        except TypeError as e:
            raise _fail(op, str(e)) from None


def verify_block(block: Block, visible: set[int], owner: Operation) -> None:
    for a in block.args:
        visible.add(id(a))
    if not block.ops or not block.ops[-1].opdef.is_terminator:
        raise _fail(owner, f"a region of {owner.name} does not end with a terminator")
    for i, op in enumerate(block.ops):
        if op.parent is not block:
            raise _fail(op, "op parent link is broken")
        if op.opdef.is_terminator and i != len(block.ops) - 1:
            raise _fail(op, f"{op.name} must be the last op of its block")
        if op.name == "func.func":
            raise _fail(op, "functions cannot nest")
        verify_op(op, visible)
        for r in op.results:
            visible.add(id(r))


def verify_module(module: Module) -> None:
    """Verify every function of ``module``; raises ``KdslVerifyError``."""
    names: set[str] = set()
    for func in module.funcs:
        if func.name != "func.func":
            raise _fail(func, "only func.func ops may appear at module level")
        name = func.attrs.get("sym_name")
        if name in names:
            raise _fail(func, f"function @{name} is defined twice")
        names.add(name)
    for func in module.funcs:
        verify_op(func, set())
        for op in func.walk():
            if op.name == "func.call":
                _verify_call(module, op)


def _verify_call(module: Module, op: Operation) -> None:
    callee = op.attrs["callee"]
    if not module.has_func(callee):
        raise _fail(op, f"call to undefined function @{callee}")
    f = module.get_func(callee)
    want_args = [a.type for a in f.regions[0].block.args]
    got_args = [v.type for v in op.operands]
    if want_args != got_args:
        raise _fail(op, f"@{callee} takes ({_fmt(want_args)}), called with ({_fmt(got_args)})")
    want_res = list(f.attrs.get("res_types", []))
    if [r.type for r in op.results] != want_res:
        raise _fail(op, f"@{callee} returns ({_fmt(want_res)})")


def _fmt(ts) -> str:
    return ", ".join(map(str, ts))


def defined_values(block: Block) -> list[Value]:
    """Block arguments and results of the block's ops (not nested ones)."""
    out: list[Value] = list(block.args)
    for op in block.ops:
        out.extend(op.results)
    return out
