"""The ``pyexec`` backend: kdsl IR -> Python source -> ``compile()`` -> a loop over threads.

What the compile driver calls, in order (see kdsl's docs/backends.md):

- it runs ``pipeline`` (the standard one) and any debug checks on the module;
- ``load(job)`` asks ``job.artifact(target)`` for the kernel's code object. The driver
  looks the kernel up in the kernel cache and, on a miss, calls ``build(job, target)``
  (the Python source as bytes, which the cache stores) and then ``load_artifact`` (the
  source compiled by ``compile()``, once per process);
- ``launch`` runs the kernel function once per thread.

``kdsl ir FILE.py:KERNEL --backend pyexec --stage python`` prints the source (``emit``).
"""

from __future__ import annotations

import itertools
import linecache
import sys
import traceback
from collections.abc import Sequence
from types import CodeType
from typing import Any

import numpy as np

from kdsl.backends.base import Backend, CompiledKernel, Job, launch_size
from kdsl.errors import KdslError, KdslRuntimeError
from kdsl.ir import CATALOG, Module, Operation
from kdsl_pyexec import codegen

#: The one target: the source is the same for every Python, but the code object is not.
TARGET = f"cpython-{sys.version_info.major}.{sys.version_info.minor}"


class ThreadContext:
    """The ``ctx`` the catalog's interp rules receive from generated code.

    Generated code runs regions and calls itself, so rules only ever ask for the
    thread index (``kd.tid``) and the kernel's name (for messages).
    """

    __slots__ = ("index", "kernel_name", "linear")

    def __init__(self, kernel_name: str) -> None:
        self.kernel_name = kernel_name
        self.linear = np.int32(0)
        self.index: tuple = (np.int32(0),)

    def tid(self, dim: int, ndim: int) -> np.int32:
        """The linear index (``ndim == 1``) or component ``dim`` of the n-d index."""
        return self.linear if ndim == 1 else self.index[dim]

    def run_region(self, region: Any, args: Any) -> list:
        raise KdslError("pyexec: generated code runs regions itself (internal error)")

    def call(self, callee: str, args: Any) -> list:
        raise KdslError("pyexec: generated code calls functions itself (internal error)")


class PyKernel:
    """The payload of a compiled kernel: the module's Python functions and facts."""

    def __init__(self, fn: Any, ops: list[Operation], filename: str, tid_ndims: set[int]):
        self.fn = fn
        self.ops = ops
        self.filename = filename
        self.tid_ndims = tid_ndims


class PyExecBackend(Backend):
    """Runs kernels as generated Python on the host, one thread after another."""

    name = "pyexec"
    version = "1"
    capabilities = frozenset({"fp16", "fp32", "fp64", "int8", "int16", "int64", "atomics"})
    emit_stages = ("python",)

    def devices(self) -> list[str]:
        return ["cpu"]

    def emit(self, module: Module, stage: str, options: dict[str, Any], checked: bool) -> str:
        if stage != "python":
            return super().emit(module, stage, options, checked)
        return codegen.emit_python(module)

    def build(self, job: Job, target: str) -> bytes:
        """A cache miss: the module's Python source is the artifact the cache stores."""
        return codegen.emit_python(job.module).encode()

    def load_artifact(self, job: Job, target: str, data: bytes) -> tuple[CodeType, str]:
        """The source compiled to a code object (once per cache key per process).

        It names no op of ``job``: ``load`` runs it against each job's own module.
        """
        source = data.decode()
        filename = f"<kdsl-pyexec {job.symbol} {job.key(target)[:12]}>"
        lines = source.splitlines(keepends=True)
        linecache.cache[filename] = (len(source), None, lines, filename)  # for tracebacks
        return compile(source, filename, "exec"), filename

    def load(self, job: Job) -> CompiledKernel:
        code, filename = job.artifact(TARGET)
        ops = codegen.module_ops(job.module)
        namespace: dict[str, Any] = {"CATALOG": CATALOG, "OPS": ops, "CONST": codegen.CONST}
        exec(code, namespace)
        names = dict(codegen.functions(job.module))
        payload = PyKernel(namespace[names[job.symbol]], ops, filename, _tid_ndims(job))
        meta = {"tid_ndims": sorted(payload.tid_ndims), "cache_key": job.key(TARGET)}
        return CompiledKernel(self.name, job.symbol, job.module, payload, meta)

    def launch(
        self,
        compiled: CompiledKernel,
        dims: tuple[int, ...],
        args: Sequence[Any],
        stream: Any = None,
    ) -> None:
        k: PyKernel = compiled.payload
        name = compiled.metadata.get("name") or compiled.symbol
        launch_size(compiled, dims, k.tid_ndims, self.name)
        ctx = ThreadContext(name)
        fn, i32, args = k.fn, np.int32, tuple(args)
        idx: tuple = ()
        with np.errstate(all="ignore"):
            try:
                if len(dims) == 1:
                    for i in range(int(dims[0])):
                        ctx.linear = i32(i)
                        fn(ctx, *args)
                else:
                    grid = itertools.product(*(range(int(d)) for d in dims))
                    for linear, idx in enumerate(grid):
                        ctx.linear = i32(linear)
                        ctx.index = tuple(i32(i) for i in idx)
                        fn(ctx, *args)
            except KdslError as e:
                raise e.add_context(f"in thread {_where(ctx, dims)} of kernel '{name}'") from None
            except Exception as e:
                op = _failing_op(k, e)
                err = KdslRuntimeError(
                    f"the pyexec backend failed on {op.name if op else '?'}: "
                    f"{type(e).__name__}: {e}",
                    op.loc if op else None,
                    name,
                )
                raise err.add_context(f"in thread {_where(ctx, dims)} of kernel '{name}'") from e


def _where(ctx: ThreadContext, dims: tuple[int, ...]) -> Any:
    return int(ctx.linear) if len(dims) == 1 else tuple(int(i) for i in ctx.index)


def _failing_op(k: PyKernel, e: BaseException) -> Operation | None:
    """The op whose generated line raised ``e`` (innermost frame of the kernel's code)."""
    found = None
    for frame in traceback.extract_tb(e.__traceback__):
        if frame.filename == k.filename:
            n = codegen.op_at_line(linecache.getline(k.filename, frame.lineno or 0))
            if n is not None:
                found = k.ops[n]
    return found


def _tid_ndims(job: Job) -> set[int]:
    """The ``ndim`` of every ``kd.tid`` in the kernel and the functions it calls."""
    seen, todo, out = set(), [job.symbol], set()
    while todo:
        sym = todo.pop()
        if sym in seen or not job.module.has_func(sym):
            continue
        seen.add(sym)
        for op in job.module.get_func(sym).walk():
            if op.name == "kd.tid":
                out.add(op.attrs["ndim"])
            elif op.name == "func.call":
                todo.append(op.attrs["callee"])
    return out
