"""NVRTC through CuPy's low-level binding: options, compilation, error mapping.

kdsl passes every option itself (CuPy's ``RawModule`` would add ``-ftz=true``):

- default builds keep IEEE behaviour identical to the cpu backend:
  ``--ftz=false --prec-div=true --prec-sqrt=true --fmad=false`` (no flush of
  subnormals, correctly rounded division and square root, no contraction of a
  multiply and an add into an FMA);
- ``fast_math`` builds use ``--use_fast_math`` (flush to zero, approximate division,
  square root and transcendentals, FMA contraction);
- always ``--gpu-architecture=sm_XX`` (a cubin for that GPU), ``--std=c++17`` and
  ``--generate-line-info`` (profilers map instructions to the Python lines the
  ``#line`` directives name; it does not change the code).

A compile error becomes a ``KdslError`` naming the user's Python file and line
(NVRTC reports the ``#line`` location) with that source line shown.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import os
import re
import sys

from kdsl.backends.cuda.names import UNIT_NAME
from kdsl.backends.facts import stored_fact
from kdsl.errors import KdslError
from kdsl.ir.core import Loc, Module

#: The architecture compile-only builds use when no GPU is visible.
DEFAULT_ARCH = "sm_90"


@functools.cache
def _log_line() -> re.Pattern[str]:
    """A line of NVRTC's log (compiled on the first error: a cache hit never reads one)."""
    return re.compile(
        r"^(?P<file>.*?)\((?P<line>\d+)\): (?P<sev>catastrophic error|error|warning)\S*: "
        r"(?P<msg>.*)$"
    )


class Binary:
    """What one NVRTC compilation gives (a plain class: a dataclass costs a warm start
    about 0.5 ms to define)."""

    __slots__ = ("cubin", "log", "ptx")

    def __init__(self, ptx: str, cubin: bytes, log: str) -> None:
        self.ptx = ptx
        self.cubin = cubin
        self.log = log


def options(arch: str, fast_math: bool = False) -> list[str]:
    """The NVRTC options of a build for ``arch`` (``sm_90``...); see the module docstring."""
    opts = [f"--gpu-architecture={arch}", "--std=c++17", "--generate-line-info"]
    if fast_math:
        opts.append("--use_fast_math")
    else:
        opts += ["--ftz=false", "--prec-div=true", "--prec-sqrt=true", "--fmad=false"]
    return opts


#: How to install the cuda backend's dependencies, as the README says.
INSTALL_HINT = 'pip install -e ".[cuda13]", or ".[cuda12]" for a CUDA 12 driver'


def _nvrtc():
    try:
        from cupy_backends.cuda.libs import nvrtc
    except ImportError as e:  # pragma: no cover - depends on the install
        raise KdslError(f"the cuda backend needs CuPy with NVRTC ({INSTALL_HINT}): {e}") from None
    return nvrtc


@functools.cache
def version() -> str:
    """NVRTC's version, ``"13.0"`` (a stored fact: see ``toolchain_facts``)."""
    return str(toolchain_facts()["version"])


@functools.cache
def supported_archs() -> tuple[int, ...]:
    """The ``sm`` numbers this NVRTC can compile for (a stored fact)."""
    return tuple(int(a) for a in toolchain_facts()["archs"])


def cache_name() -> str:
    """How kernel cache keys name the NVRTC: its version and its library's fingerprint.

    Another NVRTC (even of the same version) gives other keys, so other code is
    never read back as this one's; a cache hit learns this name without loading NVRTC.
    """
    fp = library_fingerprint()
    return f"nvrtc-{version()}" if fp is None else f"nvrtc-{version()}-{fp}"


@functools.cache
def toolchain_facts() -> dict:
    """NVRTC's version and architectures, asked of the library once per NVRTC.

    Loading ``libnvrtc`` to ask costs 160-300 ms, more than the cache hit it would
    serve; the answer is kept in the kernel cache under the library's fingerprint
    (``kdsl.backends.facts``). Without a fingerprint (no library file found where
    CuPy looks) the library is asked every time.
    """
    fp = library_fingerprint()
    if fp is None:
        return json.loads(_ask_nvrtc())
    return json.loads(stored_fact(f"nvrtc-{fp}", _ask_nvrtc))


def _ask_nvrtc() -> bytes:
    nvrtc = _nvrtc()
    major, minor = nvrtc.getVersion()
    archs = [int(a) for a in nvrtc.getSupportedArchs()]
    return json.dumps({"version": f"{major}.{minor}", "archs": archs}).encode()


#: The file names CuPy's loader (``cuda.pathfinder``) opens for NVRTC on Linux.
_LIB_NAMES = ("libnvrtc.so", "libnvrtc.so.11.2", "libnvrtc.so.12", "libnvrtc.so.13",
              "libnvrtc.so.14")  # fmt: skip
#: Where the wheels put it, under a site-packages directory.
_WHEEL_DIRS = ("nvidia/cu13/lib", "nvidia/cu12/lib", "nvidia/cuda_nvrtc/lib", "nvidia/cu14/lib")
_SYSTEM_DIRS = ("/usr/local/cuda/lib64", "/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu",
                "/usr/lib64", "/usr/lib", "/lib/x86_64-linux-gnu", "/lib64")  # fmt: skip


def _search_dirs() -> list[str]:
    """Every directory CuPy may load ``libnvrtc`` from: wheels, conda, CUDA_PATH, the system."""
    dirs = [os.path.join(p, d) for p in sys.path if p for d in _WHEEL_DIRS]
    env = os.environ
    for var in ("CONDA_PREFIX", "CUDA_PATH", "CUDA_HOME"):
        root = env.get(var)
        if root:
            dirs += [os.path.join(root, "lib64"), os.path.join(root, "lib")]
    dirs += [d for d in env.get("LD_LIBRARY_PATH", "").split(os.pathsep) if d]
    return dirs + list(_SYSTEM_DIRS)


@functools.cache
def library_fingerprint() -> str | None:
    """A digest of every ``libnvrtc`` file CuPy could load (path, size, mtime), and of
    CuPy's NVRTC binding; None when none is found (or off Linux).

    It names the NVRTC without loading it: a changed, added or removed library file
    changes it. Files are only looked at, never opened.
    """
    if not sys.platform.startswith("linux"):
        return None
    found = []
    for d in dict.fromkeys(_search_dirs()):  # each directory once, in order
        if not os.path.isdir(d):
            continue
        for name in _LIB_NAMES:
            path = os.path.join(d, name)
            try:
                st = os.stat(path)
            except OSError:
                continue
            found.append((path, st.st_size, st.st_mtime_ns))
    if not found:
        return None
    for root in _package_dirs("cupy_backends"):
        libs = os.path.join(root, "cuda", "libs")
        for name in sorted(os.listdir(libs)) if os.path.isdir(libs) else []:
            if name.startswith("nvrtc"):
                st = os.stat(os.path.join(libs, name))
                found.append((name, st.st_size, st.st_mtime_ns))
    return hashlib.sha256(repr(found).encode()).hexdigest()[:16]


def _package_dirs(name: str) -> list[str]:
    """The directories of package ``name``, without importing it: from ``sys.modules``
    when it is imported already (a launch imports CuPy first), else from its spec."""
    mod = sys.modules.get(name)
    if mod is not None and getattr(mod, "__path__", None) is not None:
        return list(mod.__path__)
    spec = importlib.util.find_spec(name)
    return list(spec.submodule_search_locations or []) if spec is not None else []


def arch_for(compute_capability: int) -> str:
    """``sm_XX`` for a device of ``compute_capability`` (e.g. 90): the newest this NVRTC
    supports that is not newer than the device (of the same major version)."""
    ok = [
        a
        for a in supported_archs()
        if a <= compute_capability and a // 10 == compute_capability // 10
    ]
    return f"sm_{max(ok) if ok else compute_capability}"


def compile_source(
    source: str, arch: str, fast_math: bool = False, module: Module | None = None, kernel: str = ""
) -> Binary:
    """Compile a generated unit; a failure raises ``KdslError`` (see ``compile_error``)."""
    nvrtc = _nvrtc()
    prog = nvrtc.createProgram(source, UNIT_NAME, [], [])
    try:
        try:
            nvrtc.compileProgram(prog, options(arch, fast_math))
        except nvrtc.NVRTCError:
            raise compile_error(nvrtc.getProgramLog(prog), source, module, kernel) from None
        cubin = nvrtc.getCUBIN(prog) if arch.startswith("sm_") else b""
        ptx = nvrtc.getPTX(prog)
        if isinstance(ptx, bytes):
            ptx = ptx.decode("utf-8", "replace")
        return Binary(ptx.rstrip("\0"), bytes(cubin), nvrtc.getProgramLog(prog))
    finally:
        nvrtc.destroyProgram(prog)


def compile_error(log: str, source: str, module: Module | None, kernel: str = "") -> KdslError:
    """A ``KdslError`` for an NVRTC log: the first error, located in the Python source.

    An error in a line mapped to the user's file gets that file and line (and, when
    an op of ``module`` is on that line, its column and span); an error in kdsl's
    own generated lines quotes the generated line.
    """
    first = None
    for text in log.splitlines():
        m = _log_line().match(text.strip())
        if m and "error" in m["sev"]:
            first = m
            break
    what = f"kernel '{kernel}'" if kernel else "a kernel"
    if first is None:
        return KdslError(f"NVRTC could not compile {what}:\n{log.strip()}")
    file, line, msg = first["file"], int(first["line"]), first["msg"].strip()
    head = f"NVRTC could not compile {what}: {msg}"
    if file == UNIT_NAME:
        lines = source.splitlines()
        code = lines[line - 1].strip() if 0 < line <= len(lines) else "?"
        return KdslError(f"{head}\n  in generated line {line} of {UNIT_NAME}: {code}")
    return KdslError(head, _find_loc(module, file, line), kernel or None)


def _find_loc(module: Module | None, file: str, line: int) -> Loc:
    """The location of an op on ``file``:``line`` (for its column), else the line itself."""
    if module is not None:
        for op in module.walk():
            loc = op.loc
            if loc is not None and loc.file == file and loc.line == line and loc.col > 0:
                return loc
    return Loc(file, line, 1)
