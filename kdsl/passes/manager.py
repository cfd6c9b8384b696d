"""The pass manager: passes as frozen dataclasses, textual pipelines, and a runner.

A pass (in the style of xDSL's ``ModulePass``) is a frozen dataclass with a
``name`` class variable, option fields and ``apply(module) -> bool`` that returns
whether it changed the module. Contract: valid IR in, valid IR out; no global
mutable state (MLIR ``PassManagement.md``).

Pipelines are strings: ``"inline,fold{max_iters=3},cse,dce"``. Options are
``key=value`` pairs inside braces, converted to the field's type.

``PassManager`` runs a pipeline with the debugging aids of ``mlir-opt``: verification
(after each pass, or once at the end with the failing pass found by a rerun; see
``kdsl.config.verify_passes``), IR dumps before/after chosen passes, per-pass timings,
and a crash reproducer (the IR before the failing pass and the pipeline, in a ``.kir``
file). The reproducer's IR is a structural copy taken before each pass
(``clone_module``) and printed only when the pass fails.
"""

from __future__ import annotations

import dataclasses
import gc
import importlib
import os
import pkgutil
import re
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import IO, Any, ClassVar, NoReturn

from kdsl import config
from kdsl.errors import KdslError, KdslVerifyError
from kdsl.ir import Block, Module, Operation, Region, print_module, verify_module
from kdsl.ir.core import OpResult, Value
from kdsl.ir.rewrite import copy_attr

#: Modules of ``kdsl.passes`` that are not passes.
_NOT_PASSES = frozenset({"manager"})


@dataclass(frozen=True)
class ModulePass:
    """Base class of passes. Subclasses are frozen dataclasses with a ``name``."""

    name: ClassVar[str] = ""

    def apply(self, module: Module) -> bool:
        """Transform ``module`` in place; return True if anything changed."""
        raise NotImplementedError

    @classmethod
    def from_options(cls, options: dict[str, str]) -> ModulePass:
        """An instance from textual options, each converted to its field's type."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        kwargs: dict[str, Any] = {}
        for key, text in options.items():
            if key not in fields:
                known = ", ".join(sorted(fields)) or "none"
                raise ValueError(f"pass {cls.name!r} has no option {key!r} (options: {known})")
            kwargs[key] = _convert_option(text, fields[key].type, f"{cls.name}{{{key}}}")
        return cls(**kwargs)

    def spec(self) -> str:
        """This pass as pipeline text, with the options that differ from defaults."""
        opts = []
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.default is not dataclasses.MISSING and value == f.default:
                continue
            opts.append(f"{f.name}={_format_option(value)}")
        return self.name + ("{" + ",".join(opts) + "}" if opts else "")


def _convert_option(text: str, annotation: Any, where: str) -> Any:
    ann = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    try:
        if ann == "bool":
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return text.lower() in ("true", "1")
        if ann == "int":
            return int(text)
        if ann == "float":
            return float(text)
    except ValueError:
        raise ValueError(f"option {where} expects a {ann}, got {text!r}") from None
    return text


def _format_option(value: Any) -> str:
    return str(value).lower() if isinstance(value, bool) else str(value)


# --- registry -------------------------------------------------------------------


def _pass_module_names() -> list[str]:
    """Names of the modules in this package that hold one pass each (not imported).

    A pass too large for one file is a package (``adjoint/``): its ``__init__``
    defines the pass, its other modules the parts.
    """
    here = os.path.dirname(__file__)
    return sorted(
        m.name
        for m in pkgutil.iter_modules([here])
        if not m.name.startswith("_") and m.name not in _NOT_PASSES
    )


def pass_names() -> list[str]:
    """Names of the built-in passes, from their file names, without importing them."""
    return [m.replace("_", "-") for m in _pass_module_names()]


def _load_pass(module_name: str) -> type[ModulePass]:
    mod = importlib.import_module(f"kdsl.passes.{module_name}")
    found = [
        obj
        for obj in vars(mod).values()
        if isinstance(obj, type)
        and issubclass(obj, ModulePass)
        and obj is not ModulePass
        and obj.__module__ == mod.__name__
    ]
    want = module_name.replace("_", "-")
    if len(found) != 1 or found[0].name != want:
        got = [c.name for c in found]
        raise RuntimeError(
            f"module kdsl.passes.{module_name} must define one pass named {want!r}: {got}"
        )
    return found[0]


def get_pass(name: str) -> type[ModulePass]:
    """The pass class called ``name``; imports only its file."""
    if name not in pass_names():
        raise ValueError(f"unknown pass {name!r}; known passes: {', '.join(pass_names())}")
    return _load_pass(name.replace("-", "_"))


def get_all_passes() -> dict[str, type[ModulePass]]:
    """Every built-in pass by name. Imports each pass file; refuses duplicate names."""
    out: dict[str, type[ModulePass]] = {}
    for module_name in _pass_module_names():
        cls = _load_pass(module_name)
        if cls.name in out:
            raise RuntimeError(f"two passes are named {cls.name!r}")
        out[cls.name] = cls
    return out


# --- pipelines ------------------------------------------------------------------

_PIPELINE_ITEM = re.compile(r"\s*([A-Za-z0-9_-]+)\s*(?:\{([^{}]*)\})?\s*(?:,|$)")


def parse_pipeline_spec(text: str) -> list[tuple[str, dict[str, str]]]:
    """``"a,b{k=v}"`` as ``[("a", {}), ("b", {"k": "v"})]`` (no lookup of names)."""
    out: list[tuple[str, dict[str, str]]] = []
    pos = 0
    text = text.strip()
    while pos < len(text):
        m = _PIPELINE_ITEM.match(text, pos)
        if m is None or m.end() == pos:
            raise ValueError(f"bad pass pipeline {text!r} at column {pos + 1}")
        options: dict[str, str] = {}
        for item in (m.group(2) or "").split(","):
            if not item.strip():
                continue
            key, eq, value = item.partition("=")
            if not eq:
                raise ValueError(f"pass option {item.strip()!r} needs the form key=value")
            options[key.strip()] = value.strip()
        out.append((m.group(1), options))
        pos = m.end()
    return out


def parse_pipeline(text: str) -> list[ModulePass]:
    """Pass instances for a pipeline string such as ``"inline,fold{max_iters=3},dce"``."""
    return [get_pass(name).from_options(opts) for name, opts in parse_pipeline_spec(text)]


def pipeline_str(passes: Iterable[ModulePass]) -> str:
    """The pipeline text that ``parse_pipeline`` turns back into ``passes``."""
    return ",".join(p.spec() for p in passes)


def _as_passes(pipeline: str | Sequence[ModulePass]) -> list[ModulePass]:
    return parse_pipeline(pipeline) if isinstance(pipeline, str) else list(pipeline)


def run_fixpoint(module: Module, pipeline: str | Sequence[ModulePass], max_iters: int = 8) -> bool:
    """Run ``pipeline`` until no pass changes the module, at most ``max_iters`` rounds.

    Like Taichi's ``full_simplify``. Returns whether anything changed.
    """
    passes = _as_passes(pipeline)
    changed_any = False
    for _ in range(max_iters):
        changed = False
        for p in passes:
            changed |= p.apply(module)
        changed_any |= changed
        if not changed:
            break
    return changed_any


# --- snapshots ------------------------------------------------------------------


def clone_module(module: Module) -> Module:
    """A structural copy of ``module`` that shares nothing mutable with it.

    New ops, values, blocks and regions with their use-lists; attribute lists and
    dicts copied, types and locations shared (they are immutable). Other attributes
    of the module object (``features``) are shared. It prints exactly as ``module``
    does, so the pass manager keeps one before each pass and prints it only when the
    pass fails: about a third of the cost of printing, and right even when a pass
    raises after changing the module. Also copies invalid IR (uses before
    definitions), which a crash reproducer may need.
    """
    new = Module(module.name)
    for key, value in vars(module).items():
        if key not in ("body", "structs"):
            setattr(new, key, value)
    new.structs = dict(module.structs)
    mapping: dict[Value, Value] = {}
    late: list[tuple[Operation, int, Value]] = []
    body = new.body
    for func in module.body.ops:
        body.append(_clone_op(func, mapping, late))
    for op, index, old in late:  # operands used before their definition
        value = mapping.get(old)
        if value is not None:  # else defined nowhere in the module: left as it is
            op.operands[index] = value
            value.uses.append((op, index))
    return new


_new = object.__new__
_ATTR_CONTAINERS = (list, dict)


def _clone_op(
    op: Operation, mapping: dict[Value, Value], late: list[tuple[Operation, int, Value]]
) -> Operation:
    # Fields are set directly (no constructor checks): this runs for every op before
    # every pass. tests/passes/test_manager_policy.py pins the slots copied here.
    new: Operation = _new(Operation)
    new.opdef = op.opdef
    new.loc = op.loc
    new.parent = None
    operands: list[Value] = []
    for i, v in enumerate(op.operands):
        nv = mapping.get(v)
        if nv is None:
            late.append((new, i, v))
        else:
            nv.uses.append((new, i))
        operands.append(v if nv is None else nv)
    new.operands = operands
    results: list[OpResult] = []
    for r in op.results:
        nr: OpResult = _new(OpResult)
        nr.type, nr.uses, nr.name_hint, nr.op, nr.index = r.type, [], r.name_hint, new, r.index
        mapping[r] = nr
        results.append(nr)
    new.results = results
    attrs = op.attrs.copy()
    for key, value in attrs.items():
        if isinstance(value, _ATTR_CONTAINERS):
            attrs[key] = copy_attr(value)
    new.attrs = attrs
    regions: list[Region] = []
    for region in op.regions:
        new_region = Region(_clone_block(region.block, mapping, late))
        new_region.parent = new
        regions.append(new_region)
    new.regions = regions
    return new


def _clone_block(
    block: Block, mapping: dict[Value, Value], late: list[tuple[Operation, int, Value]]
) -> Block:
    new = Block([a.type for a in block.args], [a.name_hint for a in block.args])
    for old_arg, new_arg in zip(block.args, new.args):
        mapping[old_arg] = new_arg
    ops = new.ops
    for op in block.ops:
        copy = _clone_op(op, mapping, late)
        copy.parent = new
        ops.append(copy)
    return new


def _is_valid(module: Module) -> bool:
    try:
        verify_module(module)
    except KdslVerifyError:
        return False
    return True


# --- the manager ----------------------------------------------------------------


class PassCrashError(KdslError):
    """A pass raised an unexpected exception; the message names the reproducer file."""


@dataclass
class PassTiming:
    """Wall time of one pass run, and whether it changed the module."""

    name: str
    seconds: float
    changed: bool


class PassManager:
    """Runs a pipeline over a module with verification, IR dumps, timing, reproducers.

    ``verify_each``: True verifies after every pass, False never verifies, None (the
    default) follows ``kdsl.config.verify_passes``: after every pass in debug mode and
    in the tests, else once after the last pass. A failure found at the end is traced
    back by rerunning the pipeline from a copy of the input with verification after
    every pass, so it raises the error (and writes the reproducer) that verifying
    after every pass would have.

    ``print_before``/``print_after`` name passes (or hold ``"all"``) whose IR is
    dumped to ``out`` (default ``sys.stderr``) under MLIR-style headers.
    """

    def __init__(
        self,
        pipeline: str | Sequence[ModulePass],
        *,
        verify_each: bool | None = None,
        print_before: Iterable[str] = (),
        print_after: Iterable[str] = (),
        print_after_all: bool = False,
        time_passes: bool = False,
        out: IO[str] | None = None,
        debuginfo: bool = False,
        reproducer_dir: str | None = None,
    ) -> None:
        self.passes = _as_passes(pipeline)
        #: Whether the module is verified at all (after every pass or at the end).
        self.verify = verify_each is not False
        #: Whether the module is verified after every pass (else once, after the last).
        self.verify_each = config.verify_each_pass() if verify_each is None else verify_each
        self.print_before = frozenset(print_before)
        self.print_after = frozenset(print_after) | ({"all"} if print_after_all else set())
        self.time_passes = time_passes
        self.out = out
        self.debuginfo = debuginfo
        self.reproducer_dir = reproducer_dir
        #: One entry per pass run, filled by ``run``.
        self.timings: list[PassTiming] = []

    @property
    def pipeline(self) -> str:
        """The pipeline as text (reproducible with ``kdsl opt -p``)."""
        return pipeline_str(self.passes)

    def run(self, module: Module) -> bool:
        """Run every pass over ``module`` in place; return whether anything changed.

        Python's cyclic garbage collector is paused during the run (unless it was
        off already). The IR is a graph of reference cycles (ops, results and their
        use-lists) and passes allocate many short-lived objects, so the collector ran
        several full collections per run, each one walking every object of the
        process: a quarter of a 3,400-op kernel's pipeline in a fresh process, more
        in a bigger one. What the run leaves behind is collected after it.
        """
        paused = gc.isenabled()
        if paused:
            gc.disable()
        try:
            return self._run(module)
        finally:
            if paused:
                gc.enable()

    def _run(self, module: Module) -> bool:
        changed_any = False
        start: Module | None = None  # the input, for tracing a deferred verify failure
        for p in self.passes:
            # The crash reproducer's IR: a copy now, printed only if the pass fails.
            before = clone_module(module)
            if start is None:
                start = before
            if self._wants(self.print_before, p):
                self._dump("Before", p, module)
            t0 = time.perf_counter()
            error: Exception | None = None
            try:
                changed = p.apply(module)
            except Exception as e:
                error = e
            if error is not None:  # handled outside the except clause: no chained context
                self._pass_failed(error, p, before, start)
            elapsed = time.perf_counter() - t0
            self.timings.append(PassTiming(p.name, elapsed, bool(changed)))
            changed_any |= bool(changed)
            if self.verify_each:
                self._verify(module, p, before)
            if self._wants(self.print_after, p):
                self._dump("After", p, module)
        if start is not None and self.verify and not self.verify_each:
            self._verify_at_end(module, start)
        if self.time_passes:
            self._stream().write(self.timing_report())
        return changed_any

    def _pass_failed(
        self, error: Exception, p: ModulePass, before: Module, start: Module
    ) -> NoReturn:
        """Raise for ``error`` from ``p``: a located user error, or a crash with reproducer."""
        deferred = self.verify and not self.verify_each
        if deferred and before is not start and not _is_valid(before):
            # Verifying after every pass would have stopped at an earlier pass that
            # left invalid IR: raise that error instead.
            self._trace_back(start)
        if isinstance(error, KdslError):
            raise error.add_context(f"during pass {p.name}") from None
        path = self.write_reproducer(print_module(before, debuginfo=True), p)
        raise PassCrashError(
            f"pass {p.name} crashed: {type(error).__name__}: {error}\n"
            f"  reproducer: {path} (run: kdsl opt {path} -p {p.spec()!r})"
        ) from error

    def _verify(self, module: Module, p: ModulePass, before: Module) -> None:
        try:
            verify_module(module)
        except KdslVerifyError as e:
            path = self.write_reproducer(print_module(before, debuginfo=True), p)
            e.add_context(f"after pass {p.name}; reproducer: {path}")
            raise

    def _verify_at_end(self, module: Module, start: Module) -> None:
        try:
            verify_module(module)
        except KdslVerifyError as e:
            error = e
        else:
            return
        self._trace_back(start)
        # The rerun passed (a pass that does not repeat itself): blame the pipeline.
        path = self._write_reproducer(print_module(start, debuginfo=True), self.pipeline)
        error.add_context(f"after pipeline {self.pipeline}; reproducer: {path}")
        raise error

    def _trace_back(self, start: Module) -> None:
        """Rerun the pipeline on a copy of ``start``, verifying after every pass.

        Raises what that run raises (the error of the pass that broke the IR, with its
        reproducer); returns only if the rerun succeeds.
        """
        rerun = PassManager(self.passes, verify_each=True, reproducer_dir=self.reproducer_dir)
        rerun.run(clone_module(start))

    @staticmethod
    def _wants(names: frozenset[str], p: ModulePass) -> bool:
        return "all" in names or p.name in names

    def _stream(self) -> IO[str]:
        return self.out if self.out is not None else sys.stderr

    def _dump(self, when: str, p: ModulePass, module: Module) -> None:
        out = self._stream()
        out.write(f"// -----// IR Dump {when} {p.name} //----- //\n")
        out.write(print_module(module, debuginfo=self.debuginfo))
        out.write("\n")

    def write_reproducer(self, ir_text: str, failing: ModulePass) -> str:
        """Write ``ir_text`` with the pipeline to a ``.kir`` file; return its path."""
        return self._write_reproducer(ir_text, failing.spec())

    def _write_reproducer(self, ir_text: str, failing: str) -> str:
        directory = self.reproducer_dir or tempfile.gettempdir()
        fd, path = tempfile.mkstemp(prefix="kdsl-repro-", suffix=".kir", dir=directory)
        with os.fdopen(fd, "w") as f:
            f.write(f"// kdsl reproducer: pass {failing} failed\n")
            f.write(f"// pipeline: {self.pipeline}\n")
            f.write(f"// RUN: kdsl opt %s -p {failing}\n")
            f.write(ir_text)
        return path

    def timing_report(self) -> str:
        """A table of wall time per pass, MLIR ``-mlir-timing`` style."""
        total = sum(t.seconds for t in self.timings) or 1e-12
        lines = ["===-------------------------------------------------------------===",
                 "                      kdsl pass execution timing",
                 "===-------------------------------------------------------------===",
                 "   Wall Time (ms)   (%)   Changed  Name"]  # fmt: skip
        for t in self.timings:
            pct = 100.0 * t.seconds / total
            mark = "yes" if t.changed else "no"
            lines.append(f"   {t.seconds * 1e3:12.3f}  {pct:5.1f}%  {mark:>7}  {t.name}")
        lines.append(f"   {total * 1e3:12.3f}  100.0%           Total")
        return "\n".join(lines) + "\n"
