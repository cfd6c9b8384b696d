"""The compile driver: the one place that runs pipelines, keys the cache and calls backends.

``compile_kernel(backend, kernel_or_module, symbol, options)`` is the path of every kernel:

1. the frontend builds the module (``kernel.build_module()``), unless a module is given;
2. the backend's declared ``pipeline`` optimizes it (unless ``optimize=False``);
3. the instrumentation the options ask for (``check_pipeline``) is inserted;
4. a ``Job`` carries the result to the backend, whose ``load`` asks ``job.artifact(target)``
   for its binary: the driver keys the kernel cache on the optimized IR, the backend's
   name and code version, the options and the target, and calls the backend's ``build``
   only on a miss (``load_artifact`` turns the bytes into something runnable, once per
   key per process).

``lower(backend, module, stage, options)`` prints any stage ``kdsl ir`` shows: ``kir``
(the frontend's output), ``kir-opt`` (after step 3), then the backend's own stages.
A backend never runs passes, never touches the cache, and never imports the runtime.
"""

from __future__ import annotations

import threading
import time
import warnings
from collections.abc import Callable, Mapping
from typing import Any

from kdsl import config
from kdsl.backends.base import Backend, CompiledKernel, Job
from kdsl.compiler import cache as kernel_cache
from kdsl.compiler import records, source_index
from kdsl.compiler.capabilities import check_capabilities
from kdsl.compiler.pipelines import check_pipeline
from kdsl.errors import KdslError
from kdsl.ir import Module, print_module
from kdsl.passes import run_pipeline

#: The stages every backend has, printed by the driver itself.
KIR, KIR_OPT = "kir", "kir-opt"


class _Artifacts:
    """A job's binaries per target, through the kernel cache (see the module docstring)."""

    def __init__(self, backend: Backend, options: dict[str, Any], symbol: str, ir_text: str):
        self.backend = backend
        self.options = {k: v for k, v in options.items() if k not in backend.target_options}
        self.symbol = symbol
        self.ir_text = ir_text
        self.loaded: dict[str, Any] = {}
        self.keys: dict[str, str] = {}
        self.job: Job | None = None
        #: Sizes of the binaries built (not loaded from the cache), for ``records``.
        self.built: list[int] = []

    def key(self, target: str) -> str:
        key = self.keys.get(target)
        if key is None:  # a sha256 of the IR text: once per target (backends ask again)
            b = self.backend
            key = self.keys[target] = kernel_cache.kernel_key(
                self.ir_text, b.name, b.code_version(), {**self.options, "kernel": self.symbol},
                b.cache_target(target),
            )  # fmt: skip
        return key

    def artifact(self, target: str) -> Any:
        hit = self.loaded.get(target)
        if hit is None:
            b, job = self.backend, self.job
            hit = self.loaded[target] = kernel_cache.get_or_build(
                self.key(target),
                lambda: self._build(target),
                lambda data: b.load_artifact(job, target, data),
            )
        return hit

    def _build(self, target: str) -> bytes:
        data = self.backend.build(self.job, target)  # type: ignore[arg-type]
        self.built.append(len(data))
        return data


def prepare_module(backend: Backend, module: Module, options: Mapping[str, Any]) -> bool:
    """Optimize ``module`` in place with ``backend``'s pipeline and instrument it.

    Returns whether instrumentation (debug checks) was inserted.
    """
    verify = verify_each(options)
    if options.get("optimize", True) and backend.pipeline:
        run_pipeline(module, backend.pipeline, verify_each=verify)
    checks = check_pipeline(options)
    if checks:
        run_pipeline(module, checks, verify_each=verify)
    check_capabilities(backend.name, frozenset(backend.capabilities), module)
    return bool(checks)


def verify_each(options: Mapping[str, Any]) -> bool | None:
    """Verify after every pass for a kernel compiled with its own ``debug`` option.

    None leaves the choice to ``kdsl.config.verify_passes`` (whose ``"auto"`` follows
    the global ``kdsl.config.mode``); an explicit ``"each"`` or ``"end"`` there wins.
    """
    return True if options.get("debug") and config.verify_passes == "auto" else None


def compile_kernel(
    backend: Backend,
    target: Any,
    symbol: str | None = None,
    options: Mapping[str, Any] | None = None,
) -> CompiledKernel:
    """Compile the kernel ``target`` (a frontend kernel, or a module plus ``symbol``).

    ``options`` are resolved kernel options (``kdsl.config.compile_options``).
    Inside ``kdsl.compiler.record_compiles()`` each call is recorded.
    """
    start = time.perf_counter()
    opts = dict(options or {})
    index_key = _index_key(backend, target, symbol, opts)
    entry = source_index.lookup(index_key) if index_key is not None else None
    pickled: bytes | None = None
    if entry is not None:  # a warm start: no frontend, no passes
        module, symbol, checked, ir_text = entry.module, target.key, entry.checked, entry.ir_text
        target.restore_build_facts(entry.facts)
    else:
        module, symbol = _module_of(target, symbol)
        if not symbol:
            raise KdslError("compile_kernel: name the kernel (symbol=...) to compile from a module")
        checked = prepare_module(backend, module, opts)
        ir_text = print_module(module, debuginfo=True) if backend.cacheable else ""
        if index_key is not None:  # pickled before the backend sees the module
            facts = target.build_facts()
            pickled = source_index.dumps(source_index.Entry(module, ir_text, checked, facts))
    binaries = _Artifacts(backend, opts, symbol, ir_text)
    job = binaries.job = Job(module, symbol, opts, checked, binaries.artifact, binaries.key)
    compiled = backend.load(job)
    if pickled is not None:  # indexed only once the kernel compiled and loaded
        source_index.store(index_key, pickled)  # type: ignore[arg-type]
    if records.recording():
        seconds = time.perf_counter() - start
        records.add_record(symbol, backend.name, seconds, module, binaries.built)
    return compiled


_SUPPORT_LOADED: set[tuple[str, str]] = set()
_SUPPORT_LOCK = threading.Lock()


def load_support(backend: Backend) -> None:
    """Load ``backend``'s support code (``Backend.support``) once per process.

    Each piece goes through the kernel cache like a kernel, keyed on its source, the
    backend's name and code version and its target, so a warm start loads it without
    building it. An optional piece that fails to build or load is a warning.
    """
    ident = (backend.name, backend.code_version())
    if ident in _SUPPORT_LOADED:
        return
    with _SUPPORT_LOCK:
        if ident in _SUPPORT_LOADED:
            return
        _SUPPORT_LOADED.add(ident)
        for code in backend.support():
            key = kernel_cache.kernel_key(
                code.text, backend.name, backend.code_version(), {"support": code.name},
                backend.cache_target(code.target),
            )  # fmt: skip
            try:
                with kernel_cache.outside_aot_directory():  # runtimes are not a module's kernels
                    kernel_cache.get_or_build(
                        key, code.build, code.load, kernel_cache.SUPPORT_STATS
                    )
            except Exception as e:
                if not code.optional:
                    raise
                warnings.warn(
                    f"kdsl: the {backend.name} backend's {code.name} could not be loaded "
                    f"({type(e).__name__}: {e}); continuing without it",
                    RuntimeWarning, stacklevel=2,
                )  # fmt: skip


def lower(
    backend: Backend,
    target: Any,
    stage: str,
    options: Mapping[str, Any] | None = None,
    *,
    prepared: bool = False,
) -> str:
    """``target`` (a kernel or a module) as text at ``stage`` of ``backend``.

    ``prepared=True`` says the module has been optimized already (``kdsl ir`` runs the
    pipeline itself, to print after each pass).
    """
    if stage not in backend.stages():
        raise KdslError(
            f"the {backend.name} backend has no stage {stage!r} (stages: {backend.stages()})"
        )
    module, _ = _module_of(target, None)
    if stage == KIR:
        return print_module(module)
    opts = dict(options or {})
    if prepared:
        checks = check_pipeline(opts)
        if checks:
            run_pipeline(module, checks)
        checked = bool(checks)
    else:
        checked = prepare_module(backend, module, opts)
    if stage == KIR_OPT:
        return print_module(module)
    return backend.emit(module, stage, opts, checked)


def _index_key(
    backend: Backend, target: Any, symbol: str | None, options: dict[str, Any]
) -> str | None:
    """The source index key of ``target`` (``source_index``), or None where it has none:
    a module given as IR, a backend without binaries, no disk cache, the index turned
    off (``KDSL_SOURCE_INDEX=0``), or a kernel whose fingerprint cannot be computed."""
    fingerprint = getattr(target, "source_fingerprint", None)
    if symbol is not None or fingerprint is None or not backend.cacheable:
        return None
    if not source_index.enabled():
        return None
    if kernel_cache.default_cache() is None:
        return None
    fn = getattr(target, "fn", None)
    memo = source_index.load_memo(fn) if fn is not None else None
    digest = fingerprint(memo)
    if memo is not None and memo.changed:  # facts read from source: recorded for next time
        source_index.store_memo(fn, memo)
    if digest is None:
        return None
    return source_index.source_key(backend, digest, target.key, options)


def _module_of(target: Any, symbol: str | None) -> tuple[Module, str]:
    if isinstance(target, Module):
        return target, symbol or ""
    build: Callable[[], Module] | None = getattr(target, "build_module", None)
    if build is None:
        raise KdslError(f"cannot compile {target!r}: expected a kernel or an IR module")
    return build(), symbol or target.key
