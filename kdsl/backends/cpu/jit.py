"""llvmlite's binding layer: host target, optimization pipeline, one MCJIT engine.

The engine is created once per process and every compiled kernel module is added
to it. C math functions the generated code calls (``tanf``, ``erf``...) are
resolved from the C math library through ``llvm.add_symbol``, so nothing depends
on what the Python executable happens to export.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading
from functools import cache
from typing import Any

import llvmlite
import llvmlite.binding as llvm

from kdsl.backends.cpu import arith, mathops

_LOCK = threading.Lock()
_ENGINE: llvm.ExecutionEngine | None = None

#: C math functions that generated code or LLVM's own lowering of intrinsics may call,
#: as the lowerings that emit them list them.
_LIBM_NAMES = (*mathops.C_FUNCTIONS, *arith.C_FUNCTIONS)

#: How deep LLVM's SLP vectorizer follows a tree of scalar operations up from its seed
#: (a reduction, a bundle of stores or compares) before it gathers the operands from
#: scalars (LLVM's default: 12). kdsl lowers vectors to scalars, so code written over a
#: struct's vec4 lanes becomes vector code only through SLP; the 4-wide leaf test of the
#: mesh point queries (``kdsl.stdlib.mesh_wide``: loads, six dot products, the region
#: selects, the closest point, a compare) is a tree some 20 operations deep, which the
#: default cut in the middle: the rest was then vectorized across x/y/z within a lane,
#: with shuffles and spills, about 1.8x slower (docs/performance.md, "CPU closest points,
#: session 12"). Process-wide (an LLVM option), so also for other llvmlite users.
SLP_MAX_DEPTH = 24


def llvm_version() -> str:
    """The LLVM version llvmlite was built with, e.g. ``"22.1.0"``."""
    return ".".join(map(str, llvm.llvm_version_info))


def version_tag() -> str:
    """llvmlite and LLVM versions, for kernel cache keys."""
    return f"llvmlite-{llvmlite.__version__}-llvm-{llvm_version()}"


@cache
def _init() -> None:
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    llvm.set_option("kdsl", f"-slp-recursion-max-depth={SLP_MAX_DEPTH}")
    _register_libm()


def _register_libm() -> None:
    # printf: kd.print (``printing``); registered here too, because a kernel loaded
    # from the cache may call it before anything imports the printing lowering.
    printf = ctypes.CDLL(None).printf
    llvm.add_symbol("printf", ctypes.cast(printf, ctypes.c_void_p).value)
    path = ctypes.util.find_library("m") or "libm.so.6"
    libm = ctypes.CDLL(path)
    for base in _LIBM_NAMES:
        for name in (base, base + "f"):
            fn = getattr(libm, name, None)
            if fn is not None:
                llvm.add_symbol(name, ctypes.cast(fn, ctypes.c_void_p).value)
    # float16 conversions LLVM may call (double -> half has no instruction on x86).
    for lib in ("libgcc_s.so.1",):
        try:
            gcc = ctypes.CDLL(lib)
        except OSError:
            continue
        for name in ("__truncdfhf2", "__truncsfhf2", "__extendhfsf2"):
            fn = getattr(gcc, name, None)
            if fn is not None:
                llvm.add_symbol(name, ctypes.cast(fn, ctypes.c_void_p).value)


def _host_machine(**kwargs: Any) -> llvm.TargetMachine:
    """A target machine for this host's CPU and features at -O3, with ``kwargs``."""
    _init()
    target = llvm.Target.from_default_triple()
    return target.create_target_machine(
        cpu=llvm.get_host_cpu_name(),
        features=llvm.get_host_cpu_features().flatten(),
        opt=3,
        **kwargs,
    )


@cache
def target_machine() -> llvm.TargetMachine:
    """A target machine for this host's CPU and features, optimizing at -O3 (for the JIT)."""
    return _host_machine(codemodel="jitdefault", jit=True)


@cache
def shared_target_machine() -> llvm.TargetMachine:
    """``target_machine`` emitting position-independent code (for ``shared_object.link``).

    The JIT's machine keeps its own code model: MCJIT places sections wherever it
    maps them, which the small code model of shared objects does not allow for.
    """
    return _host_machine(reloc="pic", codemodel="default")


def parse(text: str) -> llvm.ModuleRef:
    """Parse and verify LLVM IR text, with this host's triple and data layout."""
    tm = target_machine()
    mod = llvm.parse_assembly(text)
    mod.triple = tm.triple
    mod.data_layout = str(tm.target_data)
    mod.verify()
    return mod


def optimize(mod: llvm.ModuleRef, level: int = 3) -> llvm.ModuleRef:
    """Run LLVM's standard -O``level`` pipeline (vectorizers on) over ``mod`` in place."""
    tm = target_machine()
    pto = llvm.PipelineTuningOptions(speed_level=level)
    pto.loop_vectorization = True
    pto.slp_vectorization = True
    pb = llvm.create_pass_builder(tm, pto)
    pm = pb.getModulePassManager()
    pm.run(mod, pb)
    return mod


def assembly(mod: llvm.ModuleRef) -> str:
    """The host assembly of an (optimized) module."""
    return target_machine().emit_assembly(mod)


def _engine() -> llvm.ExecutionEngine:
    global _ENGINE
    if _ENGINE is None:
        backing = llvm.parse_assembly("")
        _ENGINE = llvm.create_mcjit_compiler(backing, target_machine())
    return _ENGINE


def target_id() -> str:
    """The target code is compiled for (triple, CPU name, CPU features), for cache keys."""
    tm = target_machine()
    return f"{tm.triple};{llvm.get_host_cpu_name()};{llvm.get_host_cpu_features().flatten()}"


def emit_object(mod: llvm.ModuleRef, shared: bool = False) -> bytes:
    """The host object code of an (optimized) module, position-independent if ``shared``."""
    return (shared_target_machine() if shared else target_machine()).emit_object(mod)


@cache
def _object_magic() -> bytes:
    """The first bytes of every object file this host's target machine emits."""
    return emit_object(parse(""))[:4]


def add_object(data: bytes, symbols: list[str]) -> dict[str, int]:
    """Load object code ``data`` into the process engine; gives the address of each symbol.

    Raises ``ValueError`` when ``data`` is not an object file of this host's format
    (LLVM would crash on it) or lacks a symbol.
    """
    if not data.startswith(_object_magic()):
        raise ValueError("not an object file of this host's format")
    with _LOCK:
        engine = _engine()
        engine.add_object_file(llvm.ObjectFileRef.from_data(data))
        engine.finalize_object()
        out = {s: engine.get_function_address(s) for s in symbols}
    missing = [s for s, a in out.items() if not a]
    if missing:
        raise ValueError(f"object code lacks {missing}")
    return out


def add_module(mod: llvm.ModuleRef, symbols: list[str]) -> dict[str, int]:
    """JIT ``mod`` into the process engine; gives the address of each of ``symbols``."""
    with _LOCK:
        engine = _engine()
        engine.add_module(mod)
        engine.finalize_object()
        engine.run_static_constructors()
        return {s: engine.get_function_address(s) for s in symbols}
