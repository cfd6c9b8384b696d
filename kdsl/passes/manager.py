"""The pass manager: passes as frozen dataclasses, textual pipelines, and a runner.

A pass (in the style of xDSL's ``ModulePass``) is a frozen dataclass with a
``name`` class variable, option fields and ``apply(module) -> bool`` that returns
whether it changed the module. Contract: valid IR in, valid IR out; no global
mutable state (MLIR ``PassManagement.md``).

Pipelines are strings: ``"inline,fold{max_iters=3},cse,dce"``. Options are
``key=value`` pairs inside braces, converted to the field's type.

``PassManager`` runs a pipeline with the debugging aids of ``mlir-opt``: verify after
each pass, IR dumps before/after chosen passes, per-pass timings, and a crash
reproducer (the IR before the failing pass and the pipeline, in a ``.kir`` file).
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import pkgutil
import re
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import IO, Any, ClassVar

from kdsl.errors import KdslError, KdslVerifyError
from kdsl.ir import Module, print_module, verify_module

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

    ``print_before``/``print_after`` name passes (or hold ``"all"``) whose IR is
    dumped to ``out`` (default ``sys.stderr``) under MLIR-style headers.
    """

    def __init__(
        self,
        pipeline: str | Sequence[ModulePass],
        *,
        verify_each: bool = True,
        print_before: Iterable[str] = (),
        print_after: Iterable[str] = (),
        print_after_all: bool = False,
        time_passes: bool = False,
        out: IO[str] | None = None,
        debuginfo: bool = False,
        reproducer_dir: str | None = None,
    ) -> None:
        self.passes = _as_passes(pipeline)
        self.verify_each = verify_each
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
        """Run every pass over ``module`` in place; return whether anything changed."""
        changed_any = False
        for p in self.passes:
            before = print_module(module, debuginfo=True)
            if self._wants(self.print_before, p):
                self._dump("Before", p, module)
            start = time.perf_counter()
            try:
                changed = p.apply(module)
            except KdslError as e:
                raise e.add_context(f"during pass {p.name}") from None
            except Exception as e:
                path = self.write_reproducer(before, p)
                raise PassCrashError(
                    f"pass {p.name} crashed: {type(e).__name__}: {e}\n"
                    f"  reproducer: {path} (run: kdsl opt {path} -p {p.spec()!r})"
                ) from e
            elapsed = time.perf_counter() - start
            self.timings.append(PassTiming(p.name, elapsed, bool(changed)))
            changed_any |= bool(changed)
            if self.verify_each:
                self._verify(module, p, before)
            if self._wants(self.print_after, p):
                self._dump("After", p, module)
        if self.time_passes:
            self._stream().write(self.timing_report())
        return changed_any

    def _verify(self, module: Module, p: ModulePass, before: str) -> None:
        try:
            verify_module(module)
        except KdslVerifyError as e:
            path = self.write_reproducer(before, p)
            e.add_context(f"after pass {p.name}; reproducer: {path}")
            raise

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
        directory = self.reproducer_dir or tempfile.gettempdir()
        fd, path = tempfile.mkstemp(prefix="kdsl-repro-", suffix=".kir", dir=directory)
        with os.fdopen(fd, "w") as f:
            f.write(f"// kdsl reproducer: pass {failing.spec()} failed\n")
            f.write(f"// pipeline: {self.pipeline}\n")
            f.write(f"// RUN: kdsl opt %s -p {failing.spec()}\n")
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
