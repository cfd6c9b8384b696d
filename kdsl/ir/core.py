"""The IR data model: values with use-lists, operations, blocks, regions, modules.

It follows MLIR's model cut down to structured control flow: an ``Operation`` has
operands, typed results, attributes, regions and a source location; a ``Region``
holds exactly one ``Block`` (kdsl has no CFG above the LLVM backend); a ``Block``
has typed arguments and a list of operations. What an op *means* (type rule,
verifier, folder, interpreter semantics) lives in its ``OpDef`` in the catalog
(``kdsl.ir.catalog``); the ``Operation`` only points at it.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from kdsl.ir.types import StructType, Type

if TYPE_CHECKING:
    from kdsl.ir.catalog import OpDef


@dataclass(frozen=True)
class Loc:
    """A source span: file, 1-based line and column, and where it ends."""

    file: str
    line: int
    col: int
    end_line: int | None = None
    end_col: int | None = None
    #: For code inlined from a function: the call it was inlined through (whose own
    #: ``caller`` goes on outwards), so an error inside library code can name the
    #: user's line. Not part of equality, hashing or the text form.
    caller: Loc | None = field(default=None, compare=False, repr=False)

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"

    def called_from(self, site: Loc) -> Loc:
        """This location seen through one more call, at ``site`` (the outermost so far)."""
        if site.line <= 0:
            return self
        outer = site if self.caller is None else self.caller.called_from(site)
        return replace(self, caller=outer)


UNKNOWN_LOC = Loc("<unknown>", 0, 0)


class Value:
    """An SSA value: the result of an op or an argument of a block."""

    __slots__ = ("type", "uses", "name_hint")

    def __init__(self, type: Type, name_hint: str | None = None) -> None:
        self.type = type
        #: (operation, operand index) for every use of this value.
        self.uses: list[tuple[Operation, int]] = []
        self.name_hint = name_hint

    def replace_all_uses_with(self, new: Value) -> None:
        """Point every use of this value at ``new``."""
        if new is self:
            return
        for op, index in list(self.uses):
            op.set_operand(index, new)

    @property
    def owner(self) -> Operation | Block:
        raise NotImplementedError


class OpResult(Value):
    """Result number ``index`` of ``op``."""

    __slots__ = ("op", "index")

    def __init__(self, type: Type, op: Operation, index: int) -> None:
        super().__init__(type)
        self.op = op
        self.index = index

    @property
    def owner(self) -> Operation:
        return self.op


class BlockArgument(Value):
    """Argument number ``index`` of ``block``."""

    __slots__ = ("block", "index")

    def __init__(self, type: Type, block: Block, index: int, name_hint: str | None) -> None:
        super().__init__(type, name_hint)
        self.block = block
        self.index = index

    @property
    def owner(self) -> Block:
        return self.block


class Operation:
    """One operation. Build it through ``Operation.create`` or the ``Builder``."""

    __slots__ = ("opdef", "operands", "results", "attrs", "regions", "loc", "parent")

    def __init__(
        self,
        opdef: OpDef,
        operands: Sequence[Value],
        result_types: Sequence[Type],
        attrs: dict[str, Any] | None = None,
        regions: Sequence[Region] = (),
        loc: Loc = UNKNOWN_LOC,
    ) -> None:
        self.opdef = opdef
        self.operands: list[Value] = []
        self.results = [OpResult(t, self, i) for i, t in enumerate(result_types)]
        self.attrs: dict[str, Any] = dict(attrs or {})
        self.regions: list[Region] = []
        self.loc = loc
        self.parent: Block | None = None
        for v in operands:
            self.add_operand(v)
        for r in regions:
            self.add_region(r)

    @property
    def name(self) -> str:
        return self.opdef.name

    @property
    def result(self) -> OpResult:
        """The single result of a one-result op."""
        if len(self.results) != 1:
            raise ValueError(f"{self.name} has {len(self.results)} results, not 1")
        return self.results[0]

    def add_operand(self, v: Value) -> None:
        if not isinstance(v, Value):
            raise TypeError(f"operand of {self.name} must be a Value, got {v!r}")
        v.uses.append((self, len(self.operands)))
        self.operands.append(v)

    def set_operand(self, index: int, v: Value) -> None:
        old = self.operands[index]
        old.uses.remove((self, index))
        v.uses.append((self, index))
        self.operands[index] = v

    def set_operands(self, values: Sequence[Value]) -> None:
        """Replace the whole operand list."""
        self.drop_operands()
        for v in values:
            self.add_operand(v)

    def drop_operands(self) -> None:
        for i, v in enumerate(self.operands):
            v.uses.remove((self, i))
        self.operands = []

    def add_region(self, region: Region) -> None:
        region.parent = self
        self.regions.append(region)

    def walk(self) -> Iterator[Operation]:
        """This op, then every op nested in its regions, in program order."""
        yield self
        for region in self.regions:
            for block in region.blocks:
                for op in list(block.ops):
                    yield from op.walk()

    def erase(self) -> None:
        """Remove this op (and everything nested in it) from its block.

        Its results must be unused.
        """
        for r in self.results:
            if r.uses:
                raise ValueError(f"erasing {self.name} whose result is still used")
        for op in list(self.walk()):
            op.drop_operands()
        if self.parent is not None:
            self.parent.ops.remove(self)
            self.parent = None

    def parent_op(self) -> Operation | None:
        """The op whose region holds this op, if any."""
        if self.parent is None or self.parent.parent is None:
            return None
        return self.parent.parent.parent

    def is_ancestor_of(self, other: Operation) -> bool:
        """True if ``other`` is nested (at any depth) in one of this op's regions."""
        p = other.parent_op()
        while p is not None:
            if p is self:
                return True
            p = p.parent_op()
        return False

    def __repr__(self) -> str:
        return f"<Operation {self.name} at {self.loc}>"


class Block:
    """A list of operations with typed arguments."""

    __slots__ = ("args", "ops", "parent", "_anchor_at")

    def __init__(
        self, arg_types: Sequence[Type] = (), arg_names: Sequence[str | None] | None = None
    ) -> None:
        names = list(arg_names) if arg_names is not None else [None] * len(arg_types)
        self.args = [BlockArgument(t, self, i, n) for i, (t, n) in enumerate(zip(arg_types, names))]
        self.ops: list[Operation] = []
        self.parent: Region | None = None
        #: Where the last ``insert_before`` anchor ended up: a guess checked before use.
        self._anchor_at = 0

    def add_arg(self, type: Type, name_hint: str | None = None) -> BlockArgument:
        arg = BlockArgument(type, self, len(self.args), name_hint)
        self.args.append(arg)
        return arg

    def erase_arg(self, index: int) -> None:
        """Remove an unused argument and renumber the rest."""
        if self.args[index].uses:
            raise ValueError("erasing a block argument that is still used")
        del self.args[index]
        for i, a in enumerate(self.args):
            a.index = i

    def append(self, op: Operation) -> Operation:
        op.parent = self
        self.ops.append(op)
        return op

    def insert(self, index: int, op: Operation) -> Operation:
        op.parent = self
        self.ops.insert(index, op)
        return op

    def insert_before(self, anchor: Operation, op: Operation) -> Operation:
        # Passes insert runs of ops before one anchor (inlining, constants): try where
        # the anchor was last time before searching the block.
        i = self._anchor_at
        if i >= len(self.ops) or self.ops[i] is not anchor:
            i = self.ops.index(anchor)
        self._anchor_at = i + 1
        return self.insert(i, op)

    def detach(self, op: Operation) -> Operation:
        """Take ``op`` out of this block without dropping its operands."""
        self.ops.remove(op)
        op.parent = None
        return op

    @property
    def terminator(self) -> Operation | None:
        if self.ops and self.ops[-1].opdef.is_terminator:
            return self.ops[-1]
        return None


class Region:
    """A region of an op. kdsl regions hold exactly one block."""

    __slots__ = ("blocks", "parent")

    def __init__(self, block: Block | None = None) -> None:
        self.blocks: list[Block] = []
        self.parent: Operation | None = None
        self.add_block(block if block is not None else Block())

    def add_block(self, block: Block) -> None:
        block.parent = self
        self.blocks.append(block)

    @property
    def block(self) -> Block:
        return self.blocks[0]


class Module:
    """A compilation unit: struct definitions and functions (``func.func`` ops)."""

    def __init__(self, name: str = "module") -> None:
        self.name = name
        self.structs: dict[str, StructType] = {}
        self.body = Block()

    @property
    def funcs(self) -> list[Operation]:
        return list(self.body.ops)

    def add_func(self, func: Operation) -> Operation:
        return self.body.append(func)

    def get_func(self, name: str) -> Operation:
        for f in self.body.ops:
            if f.attrs.get("sym_name") == name:
                return f
        raise KeyError(name)

    def has_func(self, name: str) -> bool:
        return any(f.attrs.get("sym_name") == name for f in self.body.ops)

    def walk(self) -> Iterator[Operation]:
        for f in list(self.body.ops):
            yield from f.walk()

    def add_struct(self, st: StructType) -> None:
        old = self.structs.get(st.name)
        if old is not None and old != st:
            raise ValueError(f"two different structs named {st.name}")
        self.structs[st.name] = st
