"""kdsl IR -> Python source: one Python function per IR function.

The generated module is plain, readable Python. Structured control flow becomes
Python's own ``if``/``for``/``while``; every other op is a call of its op catalog
``interp`` rule, so no op's meaning is written here a second time::

    R_arith_add = CATALOG["arith.add"].interp      # one binding per op kind used
    O7 = OPS[7]                                    # the op itself (its attributes)
    K3 = R_arith_constant(CONST, OPS[3])           # constants: evaluated at load

    def f0_saxpy(ctx, v0, v1, v2):
        v4 = R_kd_tid(ctx, O4)                     # k.py:12
        ...

``OPS`` is the list of the module's ops in walk order (``module_ops``): the source
refers to ops by position, so the same text runs against any module that prints the
same (which is what the kernel cache key guarantees). Each op's line ends with a
``# op N`` comment; ``op_at_line`` maps a failing line back to its op.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

from kdsl.errors import KdslCapabilityError
from kdsl.ir import Block, Module, Operation, Value

#: Ops whose meaning is Python's own control flow here (their interp rules need a
#: region runner; the generated code runs regions inline instead).
STRUCTURED = ("scf.if", "scf.for", "scf.while", "func.call")
#: Terminators: their operands are assigned by the op whose region they end.
TERMINATORS = ("scf.yield", "scf.condition", "func.return")

_OP_COMMENT = re.compile(r"# op (\d+)\b")


def module_ops(module: Module) -> list[Operation]:
    """Every op of ``module`` in walk order: what ``OPS[n]`` in the source refers to."""
    return list(module.walk())


def op_at_line(source_line: str) -> int | None:
    """The op number a generated line names (``# op N``), or None."""
    m = _OP_COMMENT.search(source_line)
    return int(m.group(1)) if m else None


def function_name(index: int, symbol: str) -> str:
    """The Python name of the ``index``-th IR function ``symbol``."""
    return f"f{index}_" + re.sub(r"\W", "_", symbol)


def _rule_name(op_name: str) -> str:
    return "R_" + re.sub(r"\W", "_", op_name)


class NeedsThread(Exception):
    """Raised by ``CONST`` when a rule asks for the running thread."""


class ConstContext:
    """The ``ctx`` of rules run once, at load time (``CONST``): no thread to ask about."""

    kernel_name = "?"

    def tid(self, dim: int, ndim: int) -> object:
        raise NeedsThread

    def run_region(self, region: object, args: object) -> list:
        raise NeedsThread

    def call(self, callee: str, args: object) -> list:
        raise NeedsThread


CONST = ConstContext()


def _is_constant(op: Operation) -> bool:
    """Ops evaluated once, at load: pure, no operands, no regions, one result, and a rule
    that does not ask ``ctx`` about the running thread (as interp decides it)."""
    if not (op.opdef.is_pure and not op.operands and not op.regions and len(op.results) == 1):
        return False
    try:
        op.opdef.interp(CONST, op)
    except Exception:  # NeedsThread, or a failure better reported when the op runs
        return False
    return True


class _Writer:
    def __init__(self, module: Module) -> None:
        self.number = {id(op): n for n, op in enumerate(module_ops(module))}
        self.names: dict[str, str] = {
            f.attrs["sym_name"]: function_name(i, f.attrs["sym_name"])
            for i, f in enumerate(module.funcs)
        }
        self.rules: dict[str, str] = {}  # op name -> rule variable
        self.prelude: list[str] = []  # constants and op bindings
        self.lines: list[str] = []
        self.values: dict[Value, str] = {}
        self.fresh = 0

    # -- names -----------------------------------------------------------------
    def value(self, v: Value) -> str:
        name = self.values.get(v)
        if name is None:
            name = self.values[v] = f"v{len(self.values)}"
        return name

    def temp(self, what: str) -> str:
        self.fresh += 1
        return f"_{what}{self.fresh}"

    def rule(self, op: Operation) -> str:
        if op.opdef.interp is None:
            raise KdslCapabilityError(f"the pyexec backend has no rule for {op.name}", op.loc)
        name = self.rules.get(op.name)
        if name is None:
            name = self.rules[op.name] = _rule_name(op.name)
        return name

    def emit(self, indent: int, text: str) -> None:
        self.lines.append("    " * indent + text)

    @staticmethod
    def tuple_of(names: list[str]) -> str:
        return names[0] if len(names) == 1 else "(" + ", ".join(names) + ",)"

    def assign(self, indent: int, targets: list[Value], sources: list[Value]) -> None:
        """``targets = sources`` at once (a parallel assignment, as block arguments are)."""
        if targets:
            lhs = ", ".join(self.value(t) for t in targets)
            rhs = ", ".join(self.value(s) for s in sources)
            self.emit(indent, f"{lhs} = {rhs}")

    # -- functions and blocks -------------------------------------------------
    def function(self, func: Operation) -> None:
        self.values = {}
        block = func.regions[0].block
        params = ", ".join(["ctx", *(self.value(a) for a in block.args)])
        self.emit(0, f"def {self.names[func.attrs['sym_name']]}({params}):")
        self.block(1, block)
        self.emit(0, "")

    def block(self, indent: int, block: Block) -> list[Value]:
        """Emit ``block``'s ops; gives its terminator's operands."""
        start = len(self.lines)
        term = block.terminator
        for op in block.ops:
            if op is term and op.opdef.is_terminator:
                continue
            self.op(indent, op)
        out = list(term.operands) if term is not None and term.opdef.is_terminator else []
        if term is not None and term.name == "func.return":
            self.emit(
                indent, "return " + self.tuple_of([self.value(v) for v in out]) if out else "return"
            )
        elif len(self.lines) == start:
            self.emit(indent, "pass")
        return out

    # -- ops -------------------------------------------------------------------
    def op(self, indent: int, op: Operation) -> None:
        n = self.number[id(op)]
        loc = op.loc
        where = f"  # op {n}: {op.name} @ {Path(loc.file).name}:{loc.line}:{loc.col}"
        if op.name == "scf.if":
            self.emit(indent, f"if {self.value(op.operands[0])}:{where}")
            for k, region in enumerate(op.regions):
                if k == 1:
                    self.emit(indent, "else:")
                self.assign(indent + 1, op.results, self.block(indent + 1, region.block))
        elif op.name == "scf.for":
            self.scf_for(indent, op, where)
        elif op.name == "scf.while":
            self.scf_while(indent, op, where)
        elif op.name == "func.call":
            callee = op.attrs["callee"]
            if callee not in self.names:
                raise KdslCapabilityError(f"call to unknown function '{callee}'", op.loc)
            args = ", ".join(["ctx", *(self.value(v) for v in op.operands)])
            call = f"{self.names[callee]}({args})"
            if op.results:
                call = ", ".join(self.value(r) for r in op.results) + " = " + call
            self.emit(indent, call + where)
        elif op.regions:
            raise KdslCapabilityError(f"the pyexec backend cannot emit {op.name}", op.loc)
        else:
            self.plain(indent, op, n, where)

    def plain(self, indent: int, op: Operation, n: int, where: str) -> None:
        """An op without regions: a call of its catalog interp rule."""
        rule = self.rule(op)
        if _is_constant(op):
            self.prelude.append(f"K{n} = {rule}(CONST, OPS[{n}]){where}")
            self.emit(indent, f"{self.value(op.results[0])} = K{n}")
            return
        self.prelude.append(f"O{n} = OPS[{n}]")
        call = f"{rule}({', '.join(['ctx', f'O{n}', *(self.value(v) for v in op.operands)])})"
        if len(op.results) == 1:
            call = f"{self.value(op.results[0])} = {call}"
        elif op.results:
            call = f"{', '.join(self.value(r) for r in op.results)} = {call}"
        self.emit(indent, call + where)

    def scf_for(self, indent: int, op: Operation, where: str) -> None:
        """``range`` runs exactly the catalog's iterations: ``i < ub`` going up,
        ``i > ub`` going down, none for a zero step; the induction variable keeps
        the bounds' type."""
        lb, ub, step = (self.value(v) for v in op.operands[:3])
        body = op.regions[0].block
        iv, *carried = body.args
        i, ty = self.temp("i"), self.temp("t")
        self.assign(indent, carried, op.operands[3:])
        self.emit(indent, f"{ty} = type({lb}){where}")
        self.emit(indent, f"for {i} in range(int({lb}), int({ub}), int({step})) if {step} else ():")
        self.emit(indent + 1, f"{self.value(iv)} = {ty}({i})")
        self.assign(indent + 1, carried, self.block(indent + 1, body))
        self.assign(indent, op.results, carried)

    def scf_while(self, indent: int, op: Operation, where: str) -> None:
        before, after = (r.block for r in op.regions)
        self.assign(indent, before.args, op.operands)
        self.emit(indent, f"while True:{where}")
        cond, *passed = self.block(indent + 1, before)
        self.emit(indent + 1, f"if not {self.value(cond)}:")
        self.assign(indent + 2, op.results, passed)
        self.emit(indent + 2, "break")
        self.assign(indent + 1, after.args, passed)
        self.assign(indent + 1, before.args, self.block(indent + 1, after))


def emit_python(module: Module) -> str:
    """The Python source of every function of ``module`` (see the module docstring)."""
    w = _Writer(module)
    for func in module.funcs:
        w.function(func)
    head = [
        f"# kdsl module {module.name!r}, emitted by the kdsl_pyexec backend plugin.",
        "# Globals supplied by the loader: CATALOG, OPS, CONST.",
        *(f'{var} = CATALOG["{name}"].interp' for name, var in sorted(w.rules.items())),
        *w.prelude,
        "",
        "",
    ]
    return "\n".join([*head, *w.lines]).rstrip() + "\n"


def functions(module: Module) -> Iterator[tuple[str, str]]:
    """(IR symbol, Python name) of every function of ``module``."""
    for i, f in enumerate(module.funcs):
        yield f.attrs["sym_name"], function_name(i, f.attrs["sym_name"])
