"""The kernel cache's source index: a warm start skips the frontend and the passes, and
every change that could change a kernel's code misses.

In-process tests check the fingerprint and the key (a change of the kernel's source,
a called function's, a captured constant, a closure value, a struct, an option, the
backend, kdsl's own code); fresh-process tests check the whole path: the second
process finds the kernel without building its IR or importing the pass modules,
llvmlite's binding or NVRTC, and an edit between two processes recompiles.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.cpu import BACKEND
from kdsl.compiler import cache, compile_kernel, source_index
from kdsl.frontend.fingerprint import SourceMemo, source_fingerprint
from kdsl.frontend.source import ParsedSource

ROOT = Path(wp.__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("KDSL_CACHE", raising=False)


def _load(path: Path, text: str):
    """``text`` written to ``path`` and imported as a fresh module object, named after
    ``path`` (as a new process would import it: the same name for the same file)."""
    source = textwrap.dedent(text)
    path.write_text(source)
    mod = types.ModuleType(f"srcidx_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:8]}")
    exec(compile(source, str(path), "exec"), mod.__dict__)
    return mod


BASE = """\
import kdsl as wp

SCALE = 2.0


@wp.struct
class Pair:
    a: float
    b: float


@wp.func
def inner(x: float):
    return x + 1.0


@wp.func
def outer(x: float):
    return inner(x) * SCALE


@wp.kernel
def k(out: wp.array(dtype=float)):
    i = wp.tid()
    p = Pair()
    p.a = float(i)
    out[i] = outer(p.a)
"""


def _fp(tmp_path: Path, text: str, name: str = "k") -> str | None:
    mod = _load(tmp_path / "kern.py", text)
    return source_fingerprint(getattr(mod, name))


# --------------------------------------------------------------------------- fingerprint


def test_the_fingerprint_is_stable_for_the_same_source(tmp_path):
    a = _fp(tmp_path, BASE)
    assert a is not None and len(a) == 64
    assert _fp(tmp_path, BASE) == a


@pytest.mark.parametrize(
    "edit",
    [
        ("out[i] = outer(p.a)", "out[i] = outer(p.a) + 0.0"),  # the kernel's body
        ("return x + 1.0", "return x + 2.0"),  # a function two calls down
        ("return inner(x) * SCALE", "return inner(x) * SCALE * 1.0"),  # a called function
        ("SCALE = 2.0", "SCALE = 2.5"),  # a global constant
        ("SCALE = 2.0", "SCALE = wp.constant(2)"),  # same value, another type
        ("    b: float", "    b: wp.float64"),  # a struct's field type
        ("    b: float", "    b: float\n    c: int"),  # a struct's new field
        ("@wp.kernel\ndef k", "\n@wp.kernel\ndef k"),  # a line shift: the IR's locations
        ("def k(out: wp.array(dtype=float))", "def k(out: wp.array(dtype=wp.float64))"),
    ],
    ids=["kernel", "transitive-func", "func", "constant", "constant-type", "struct-field",
         "struct-new-field", "line-shift", "param-type"],
)  # fmt: skip
def test_every_edit_changes_the_fingerprint(tmp_path, edit):
    old, new = edit
    assert old in BASE
    assert _fp(tmp_path, BASE) != _fp(tmp_path, BASE.replace(old, new, 1))
    # Also through a memo of the unedited file's facts: the edit is seen, never the memo.
    memo = SourceMemo()
    base = source_fingerprint(_load(tmp_path / "kern.py", BASE).k, memo)
    assert memo.changed and base == _fp(tmp_path, BASE)
    edited = _load(tmp_path / "kern.py", BASE.replace(old, new, 1))
    through_memo = source_fingerprint(edited.k, _round_trip(memo))
    assert through_memo == _fp(tmp_path, BASE.replace(old, new, 1)) != base


def _round_trip(memo: SourceMemo) -> SourceMemo:
    """``memo`` as another process reads it from the cache."""
    return SourceMemo.from_json(json.loads(json.dumps(memo.as_json())))


def _count_parses(monkeypatch) -> list[str]:
    """The names of the functions whose source is parsed from now on."""
    parsed: list[str] = []
    init = ParsedSource.__init__

    def counting(self, fn):
        parsed.append(fn.__name__)
        init(self, fn)

    monkeypatch.setattr(ParsedSource, "__init__", counting)
    return parsed


def test_a_memo_gives_the_fingerprint_without_reading_the_source(tmp_path, monkeypatch):
    memo = SourceMemo()
    first = source_fingerprint(_load(tmp_path / "kern.py", BASE).k, memo)
    assert first is not None and memo.changed
    assert {w[2] for w in memo.facts} == {"k", "inner", "outer"}
    parsed = _count_parses(monkeypatch)
    again = _load(tmp_path / "kern.py", BASE)  # new objects, as in a new process
    warm = _round_trip(memo)
    assert source_fingerprint(again.k, warm) == first
    assert parsed == [] and not warm.changed
    # Any change of the file's bytes (here a comment at its end) sets the memo aside.
    _load(tmp_path / "kern.py", BASE + "# a comment\n")
    edited = _load(tmp_path / "kern.py", BASE + "# a comment\n")
    assert source_fingerprint(edited.k, _round_trip(memo)) == first  # same text and lines
    assert sorted(parsed) == ["inner", "k", "outer"]


def test_a_memo_keeps_only_the_facts_it_used(tmp_path):
    memo = SourceMemo()
    source_fingerprint(_load(tmp_path / "kern.py", BASE).k, memo)
    moved = _round_trip(memo)  # every function one line down: new places, new facts
    source_fingerprint(_load(tmp_path / "kern.py", "\n" + BASE).k, moved)
    assert moved.changed and len(moved.facts) == 6
    assert sorted(w[1] for w, _ in _round_trip(moved).facts.items()) == sorted(
        w[1] + 1 for w in memo.facts
    )


def test_facts_of_a_source_parsed_before_are_not_recorded(tmp_path):
    mod = _load(tmp_path / "kern.py", BASE)
    assert mod.k.src.text  # parsed by someone else first: maybe from an older file
    memo = SourceMemo()
    assert source_fingerprint(mod.k, memo) == _fp(tmp_path, BASE)
    assert {w[2] for w in memo.facts} == {"inner", "outer"}


def test_facts_are_not_recorded_from_a_stale_linecache(tmp_path):
    """``linecache`` trusts a file's size and time: a same-size edit that keeps both is
    served from its old copy. The memo then records nothing for that function."""
    path = tmp_path / "kern.py"
    assert _load(path, BASE).k.src.text  # linecache now holds BASE
    st = path.stat()
    edited = BASE.replace("out[i] = outer(p.a)", "out[i] = inner(p.a)")
    assert len(edited) == len(BASE)
    fresh = _load(path, edited)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    memo = SourceMemo()
    source_fingerprint(fresh.k, memo)
    assert "k" not in {w[2] for w in memo.facts}


def test_a_bad_memo_is_discarded(tmp_path):
    mod = _load(tmp_path / "kern.py", BASE)
    compile_kernel(BACKEND, mod.k, options={})
    memos = cache.DiskCache(cache.default_cache().directory, cache.MEMO_SUFFIX)
    (entry,) = memos.entries()
    assert entry.name == source_index.memo_key(mod.k.fn) + cache.MEMO_SUFFIX
    memos.store(source_index.memo_key(mod.k.fn), b"[[1, 2]]")  # valid header, bad facts
    discarded = source_index.STATS.discarded
    assert source_index.load_memo(mod.k.fn).facts == {}
    assert source_index.STATS.discarded == discarded + 1 and memos.entries() == []


def test_a_rebound_global_changes_the_fingerprint_in_process(tmp_path):
    mod = _load(tmp_path / "kern.py", BASE)
    before = source_fingerprint(mod.k)
    mod.SCALE = 3.0
    assert source_fingerprint(mod.k) != before
    mod.SCALE = 2.0
    assert source_fingerprint(mod.k) == before


FACTORY = """\
import numpy as np
import kdsl as wp


def make(value):
    @wp.kernel
    def k(out: wp.array(dtype=float)):
        out[wp.tid()] = value
    return k


TABLE = (1.0, 2.0)
VEC = wp.vec3(1.0, 2.0, 3.0)
ARR = np.arange(4, dtype=np.float32)


@wp.kernel
def reads_values(out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = TABLE[1] + VEC[2] + ARR.shape[0]
"""


def test_closure_values_and_containers_are_digested(tmp_path):
    mod = _load(tmp_path / "kern.py", FACTORY)
    two, three = source_fingerprint(mod.make(2.0)), source_fingerprint(mod.make(3.0))
    assert None not in (two, three) and two != three
    assert source_fingerprint(mod.make(2.0)) == two
    before = source_fingerprint(mod.reads_values)
    assert before is not None
    for name, value in (("TABLE", (1.0, 2.5)), ("VEC", wp.vec3(1.0, 2.0, 4.0)),
                        ("ARR", np.arange(5, dtype=np.float32))):  # fmt: skip
        old = getattr(mod, name)
        setattr(mod, name, value)
        assert source_fingerprint(mod.reads_values) != before, name
        setattr(mod, name, old)
    assert source_fingerprint(mod.reads_values) == before


OPAQUE = """\
import kdsl as wp


class Settings:
    n = 3


class Loud(float):
    def __repr__(self):
        raise RuntimeError("no repr")


LOUD = Loud(1.0)


def helper():
    return 4


SETTINGS = Settings()
out = object()  # a global of a parameter's name: never looked up


@wp.kernel
def uses_object(a: wp.array(dtype=int)):
    a[wp.tid()] = SETTINGS.n


@wp.kernel
def uses_bare_object(a: wp.array(dtype=int)):
    s = SETTINGS
    a[wp.tid()] = s.n


@wp.kernel
def uses_static_call(a: wp.array(dtype=int)):
    a[wp.tid()] = wp.static(helper())


@wp.kernel
def param_named_like_a_global(out: wp.array(dtype=int)):
    out[wp.tid()] = 1


@wp.kernel
def reads_a_value_that_raises(a: wp.array(dtype=float)):
    a[wp.tid()] = LOUD
"""


def test_values_it_cannot_digest_leave_the_kernel_keyed_by_its_ir(tmp_path):
    mod = _load(tmp_path / "kern.py", OPAQUE)
    assert source_fingerprint(mod.uses_bare_object) is None
    via_attribute = source_fingerprint(mod.uses_object)  # the value read is SETTINGS.n
    assert via_attribute is not None
    mod.SETTINGS.n = 5
    assert source_fingerprint(mod.uses_object) not in (None, via_attribute)
    assert source_fingerprint(mod.uses_static_call) is None
    assert source_fingerprint(mod.param_named_like_a_global) is not None
    assert source_fingerprint(mod.reads_a_value_that_raises) is None  # never an error
    # Still compiled and run, through the IR key alone (no index entry).
    stored = source_index.STATS.stored
    a = wp.zeros(2, dtype=int)
    wp.launch(mod.uses_static_call, 2, inputs=[a], backend=BACKEND)
    assert a.numpy().tolist() == [4, 4]
    assert source_index.STATS.stored == stored


RECURSIVE_AND_GENERIC = """\
from typing import Any

import kdsl as wp


@wp.func
def fact(n: int) -> int:
    if n <= 1:
        return 1
    return n * fact(n - 1)


@wp.kernel
def k(out: wp.array(dtype=int)):
    out[wp.tid()] = fact(4)


@wp.kernel
def g(a: wp.array(dtype=Any)):
    a[wp.tid()] = a[wp.tid()] + a[wp.tid()]
"""


def test_recursive_functions_and_generic_instances(tmp_path):
    mod = _load(tmp_path / "kern.py", RECURSIVE_AND_GENERIC)
    assert source_fingerprint(mod.k) is not None
    assert mod.g.source_fingerprint() is None  # generic: only its instances compile
    f32 = wp.overload(mod.g, [wp.array(dtype=wp.float32)])
    i32 = wp.overload(mod.g, [wp.array(dtype=wp.int32)])
    assert None not in (f32.source_fingerprint(), i32.source_fingerprint())
    assert f32.source_fingerprint() != i32.source_fingerprint()


# --------------------------------------------------------------------------- key


def test_the_key_covers_options_backend_and_kdsl_itself(monkeypatch):
    from kdsl.backends.cuda import BACKEND as CUDA

    base = source_index.source_key(BACKEND, "f" * 64, "k_1234", {"fast_math": False})
    assert base == source_index.source_key(BACKEND, "f" * 64, "k_1234", {"fast_math": False})
    variants = [
        source_index.source_key(BACKEND, "e" * 64, "k_1234", {"fast_math": False}),
        source_index.source_key(BACKEND, "f" * 64, "k_5678", {"fast_math": False}),
        source_index.source_key(BACKEND, "f" * 64, "k_1234", {"fast_math": True}),
        source_index.source_key(BACKEND, "f" * 64, "k_1234", {"fast_math": False, "debug": True}),
        source_index.source_key(CUDA, "f" * 64, "k_1234", {"fast_math": False}),
    ]
    monkeypatch.setattr(type(BACKEND), "code_version", lambda self: "another backend build")
    variants.append(source_index.source_key(BACKEND, "f" * 64, "k_1234", {"fast_math": False}))
    monkeypatch.undo()
    monkeypatch.setattr(source_index, "kdsl_code_digest", lambda: "another kdsl")
    variants.append(source_index.source_key(BACKEND, "f" * 64, "k_1234", {"fast_math": False}))
    assert len(set(variants)) == len(variants) and base not in variants


def test_the_code_digest_sees_an_edit_of_kdsl(tmp_path):
    root = tmp_path / "kdsl"
    (root / "passes" / "sub").mkdir(parents=True)
    (root / "backends").mkdir()
    (root / "types.py").write_text("A = 1\n")
    deep = root / "passes" / "sub" / "fold.py"
    deep.write_text("B = 1\n")
    (root / "backends" / "x.py").write_text("C = 1\n")  # a backend: its own code_version
    first = source_index.code_digest(str(root))
    assert source_index.code_digest(str(root)) == first
    (root / "backends" / "x.py").write_text("C = 22\n")
    assert source_index.code_digest(str(root)) == first
    deep.write_text("B = 2\n")
    second = source_index.code_digest(str(root))
    assert second != first
    os.utime(deep, ns=(1, 1))  # the same size, another time
    assert source_index.code_digest(str(root)) != second
    (root / "types.py").write_text("A = 2\n")
    assert source_index.code_digest(str(root)) not in (first, second)


# --------------------------------------------------------------------------- in process


def test_a_hit_builds_no_ir_and_gives_the_same_kernel(tmp_path, monkeypatch):
    mod = _load(tmp_path / "kern.py", BASE)
    cold = compile_kernel(BACKEND, mod.k, options={})
    assert source_index.STATS.stored >= 1
    cache.MEMORY.clear()  # as a new process: only the disk has the kernel
    again = _load(tmp_path / "kern.py", BASE)  # new kernel objects, same source
    monkeypatch.setattr(type(again.k), "_build", _refuse)
    hits = source_index.STATS.hits
    warm = compile_kernel(BACKEND, again.k, options={})
    assert source_index.STATS.hits == hits + 1
    assert warm.metadata["cache_key"] == cold.metadata["cache_key"]
    assert again.k.tid_ndim == 1
    out = wp.zeros(4, dtype=float)
    wp.launch(again.k, 4, inputs=[out], backend=BACKEND)
    np.testing.assert_allclose(out.numpy(), [(i + 1.0) * 2.0 for i in range(4)])


def _compiled_index_entry(tmp_path):
    """Compile BASE once; the index cache and the key of its one entry."""
    compile_kernel(BACKEND, _load(tmp_path / "kern.py", BASE).k, options={})
    index = cache.DiskCache(cache.default_cache().directory, cache.INDEX_SUFFIX)
    (entry,) = index.entries()
    return index, entry.name[: -len(cache.INDEX_SUFFIX)]


def test_a_bad_index_entry_is_discarded_and_rebuilt(tmp_path):
    index, key = _compiled_index_entry(tmp_path)
    index.store(key, b"not a pickle")  # valid header, payload that does not load
    cache.MEMORY.clear()
    discarded, stored = source_index.STATS.discarded, source_index.STATS.stored
    compile_kernel(BACKEND, _load(tmp_path / "kern.py", BASE).k, options={})
    assert source_index.STATS.discarded == discarded + 1
    assert source_index.STATS.stored == stored + 1  # rebuilt from the frontend


class NotIR:
    """A class outside kdsl: an index entry naming it is refused on load."""


def test_an_entry_naming_a_class_outside_kdsl_is_refused(tmp_path):
    import pickle

    index, key = _compiled_index_entry(tmp_path)
    index.store(key, pickle.dumps(NotIR()))
    discarded = source_index.STATS.discarded
    assert source_index.lookup(key) is None
    assert source_index.STATS.discarded == discarded + 1 and index.entries() == []


def test_options_key_apart_and_clear_removes_index_entries(tmp_path):
    mod = _load(tmp_path / "kern.py", BASE)
    compile_kernel(BACKEND, mod.k, options={})
    compile_kernel(BACKEND, mod.k, options={"debug": True})
    index = cache.DiskCache(cache.default_cache().directory, cache.INDEX_SUFFIX)
    assert len(index.entries()) == 2
    wp.clear_kernel_cache()
    assert index.entries() == []


def test_without_a_disk_cache_there_is_no_index(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE", "0")
    mod = _load(tmp_path / "kern.py", BASE)
    stored, misses = source_index.STATS.stored, source_index.STATS.misses
    compile_kernel(BACKEND, mod.k, options={})
    assert (source_index.STATS.stored, source_index.STATS.misses) == (stored, misses)


def test_the_index_can_be_turned_off_alone(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_SOURCE_INDEX", "0")
    mod = _load(tmp_path / "kern.py", BASE)
    stored, misses = source_index.STATS.stored, source_index.STATS.misses
    builds = cache.STATS.builds
    compile_kernel(BACKEND, mod.k, options={})
    assert (source_index.STATS.stored, source_index.STATS.misses) == (stored, misses)
    assert cache.STATS.builds == builds + 1  # the kernel itself is still cached


def _refuse(*args, **kwargs):
    raise AssertionError("a source index hit must not build the kernel's IR")


# --------------------------------------------------------------------------- fresh processes

HELPERS = """\
import kdsl as wp

SCALE = 2.0


@wp.struct
class Body:
    x: float
    m: float


@wp.func
def weigh(b: Body):
    return b.x * b.m * SCALE
"""

KERNELS = """\
import kdsl as wp
from helpers import Body, weigh


@wp.kernel
def k(out: wp.array(dtype=float)):
    i = wp.tid()
    b = Body()
    b.x = float(i)
    b.m = 3.0
    out[i] = weigh(b)
"""

RUN = """\
import json, os, sys
import kdsl as wp
from kdsl.frontend.kernel import Kernel

device = sys.argv[1]
if device == "cuda-compile":
    from kdsl.backends.cuda import BACKEND
else:
    from kdsl.backends.registry import get_backend
    from kdsl.runtime.launch import default_backend_for
    BACKEND = get_backend(default_backend_for(device))
before = set(sys.modules)  # after importing the backend: what the compile path imports
built = []
_build = Kernel._build
def counting_build(self):
    built.append(self.name)
    return _build(self)
Kernel._build = counting_build
from kdsl.frontend.source import ParsedSource
parsed = []
_parse = ParsedSource.__init__
def counting_parse(self, fn):
    parsed.append(fn.__name__)
    _parse(self, fn)
ParsedSource.__init__ = counting_parse

from kdsl.compiler import cache, source_index
# kdsl's own code is keyed by test_the_code_digest_sees_an_edit_of_kdsl; pinned here so
# that others editing this checkout meanwhile do not turn a hit into a miss.
source_index.kdsl_code_digest = lambda: "pinned for the test"
from kern import k

def nvrtc_mapped():
    maps = open("/proc/self/maps").read() if os.path.exists("/proc/self/maps") else ""
    return "libnvrtc" in maps

CODEGEN = ("kdsl.backends.cpu.lower", "kdsl.backends.cuda.lower", "kdsl.backends.cuda.ops")
steps = {}
if device == "cuda-compile":  # no GPU needed: compiled for sm_90, never launched
    from kdsl.backends.cuda import BACKEND
    from kdsl.compiler import compile_kernel
    compiled = compile_kernel(BACKEND, k, options={"arch": "sm_90"})
    out = [len(compiled.payload.cubin("sm_90")) > 0]
else:
    a = wp.zeros(4, dtype=float, device=device)
    steps["allocated"] = nvrtc_mapped()
    wp.launch(k, 4, outputs=[a], device=device)
    steps["launched"] = nvrtc_mapped()
    out = a.numpy().tolist()
new = sorted(set(sys.modules) - before)
print(json.dumps({
    "out": out, "built": built, "parsed": parsed, "index": vars(source_index.STATS),
    "kernel_builds": cache.STATS.builds, "new_modules": new,
    "nvrtc_mapped": nvrtc_mapped(), "nvrtc_steps": steps,
    "codegen_imported": sorted(m for m in sys.modules if m in CODEGEN),
}))
"""


@pytest.fixture
def project(tmp_path) -> Path:
    (tmp_path / "helpers.py").write_text(HELPERS)
    (tmp_path / "kern.py").write_text(KERNELS)
    (tmp_path / "run.py").write_text(RUN)
    return tmp_path


def _run(project: Path, device: str = "cpu") -> dict:
    paths = [str(project), str(ROOT), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]  # fmt: skip
    # No bytecode files: an edit of the same size within a second would read a stale one.
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths), "PYTHONDONTWRITEBYTECODE": "1"}
    proc = subprocess.run([sys.executable, str(project / "run.py"), device], cwd=project,
                          env=env, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _expected(scale: float = 2.0, m: float = 3.0) -> list[float]:
    return [i * m * scale for i in range(4)]


def _lowering_modules(new: list[str]) -> list[str]:
    """Modules a hit must not import: passes, llvmlite's binding and IR, CuPy's NVRTC."""
    bad = ("kdsl.passes.", "llvmlite.binding", "llvmlite.ir", "cupy")
    return [m for m in new if m.startswith(bad)]


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_cpu_warm_start_skips_frontend_passes_and_llvmlite(project):
    cold = _run(project)
    assert cold["out"] == _expected() and cold["built"] == ["k"]
    assert cold["index"]["stored"] == 1
    warm = _run(project)
    assert warm["out"] == _expected()
    assert warm["built"] == [] and warm["index"]["hits"] == 1 and warm["kernel_builds"] == 0
    assert _lowering_modules(warm["new_modules"]) == []
    assert sorted(cold["parsed"]) == ["k", "weigh"]
    assert warm["parsed"] == []  # the source memo: no source read or parsed
    assert warm["codegen_imported"] == []  # nor the code generator imported


@pytest.mark.parametrize(
    "edit",
    [
        ("helpers.py", "return b.x * b.m * SCALE", "return b.x * b.m * SCALE + 1.0",
         [v + 1.0 for v in _expected()]),
        ("helpers.py", "SCALE = 2.0", "SCALE = 5.0", _expected(scale=5.0)),
        ("helpers.py", "    m: float\n", "    pad: int\n    m: float\n", _expected()),
        ("kern.py", "b.m = 3.0", "b.m = 4.0", _expected(m=4.0)),
    ],
    ids=["called-function", "constant", "struct", "kernel"],
)  # fmt: skip
def test_cpu_an_edit_between_processes_recompiles(project, edit):
    file, old, new, expected = edit
    assert _run(project)["out"] == _expected()
    _edit(project / file, old, new)
    after = _run(project)
    assert after["built"] == ["k"] and after["index"]["misses"] == 1
    np.testing.assert_allclose(after["out"], expected)
    again = _run(project)  # and the edited kernel is found from then on
    assert again["built"] == [] and again["index"]["hits"] == 1 and again["parsed"] == []


def _has_nvrtc() -> bool:
    try:
        import cupy_backends.cuda.libs.nvrtc  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.skipif(not _has_nvrtc(), reason="needs CuPy's NVRTC (compile-only, no GPU)")
def test_cuda_warm_compile_skips_frontend_passes_and_nvrtc(project):
    cold = _run(project, "cuda-compile")
    assert cold["out"] == [True] and cold["built"] == ["k"] and cold["index"]["stored"] == 1
    warm = _run(project, "cuda-compile")
    assert warm["out"] == [True] and warm["built"] == [] and warm["index"]["hits"] == 1
    assert warm["kernel_builds"] == 0 and not warm["nvrtc_mapped"]
    assert _lowering_modules(warm["new_modules"]) == [] and warm["parsed"] == []
    assert warm["codegen_imported"] == []  # the cuda backend names its entry without it
    _edit(project / "helpers.py", "SCALE = 2.0", "SCALE = 5.0")
    edited = _run(project, "cuda-compile")
    assert edited["built"] == ["k"] and edited["index"]["misses"] == 1


def _has_gpu() -> bool:
    try:
        from kdsl.backends.cuda.devices import device_count

        return device_count() > 0
    except Exception:
        return False


@pytest.mark.skipif(not _has_gpu(), reason="needs a CUDA device")
def test_cuda_warm_start_on_a_gpu_skips_frontend_and_passes(project):
    cold = _run(project, "cuda:0")
    assert cold["out"] == _expected() and cold["built"] == ["k"]
    warm = _run(project, "cuda:0")
    assert warm["out"] == _expected() and warm["built"] == [] and warm["index"]["hits"] == 1
    assert warm["kernel_builds"] == 0 and warm["parsed"] == []
    assert [m for m in warm["new_modules"] if m.startswith("kdsl.passes.")] == []
    # The compile and launch load no NVRTC (CuPy may have loaded it before, for its own
    # kernels: that is not the kernel cache's doing, and the message says so).
    steps = warm["nvrtc_steps"]
    assert steps["allocated"] or not steps["launched"], f"the launch loaded NVRTC: {steps}"


GRADIENT_KERNEL = """\
import kdsl as wp

SCALE = 2.0


@wp.kernel
def k(x: wp.array(dtype=float), loss: wp.array(dtype=float)):
    i = wp.tid()
    v = x[i]
    for _ in range(x.shape[0]):  # a run-time trip count: a tape and a counting kernel
        v = wp.sin(v)
    wp.atomic_add(loss, 0, v * SCALE)
"""

GRADIENT_RUN = """\
import json, sys
import kdsl as wp
from kdsl.compiler import cache, source_index
from kdsl.frontend.kernel import Kernel
from kdsl.frontend.source import ParsedSource

source_index.kdsl_code_digest = lambda: "pinned for the test"
built, parsed = [], []
_build, _parse = Kernel._build, ParsedSource.__init__
def counting_build(self):
    built.append(self.name)
    return _build(self)
def counting_parse(self, fn):
    parsed.append(fn.__name__)
    _parse(self, fn)
Kernel._build, ParsedSource.__init__ = counting_build, counting_parse
from kern import k

device = sys.argv[1]
x = wp.array([1.0, 2.0, 3.0], dtype=float, requires_grad=True, device=device)
loss = wp.zeros(1, dtype=float, requires_grad=True, device=device)
tape = wp.Tape()
with tape:
    wp.launch(k, 3, inputs=[x], outputs=[loss], device=device)
tape.backward(loss=loss)
print(json.dumps({"grad": x.grad.numpy().tolist(), "built": built, "parsed": parsed,
                  "index": vars(source_index.STATS), "kernel_builds": cache.STATS.builds}))
"""


def _gradient(x: float, scale: float = 2.0, n: int = 3) -> float:
    g = scale  # d/dx of scale * sin(sin(...sin(x)))
    for _ in range(n):
        g *= np.cos(x)
        x = np.sin(x)
    return g


@pytest.mark.parametrize(
    "device",
    ["cpu", pytest.param("cuda:0", marks=pytest.mark.skipif(not _has_gpu(), reason="no GPU"))],
)
def test_a_kernels_adjoint_is_found_by_its_source_too(tmp_path, device):
    (tmp_path / "kern.py").write_text(GRADIENT_KERNEL)
    (tmp_path / "run.py").write_text(GRADIENT_RUN)
    expected = [_gradient(x) for x in (1.0, 2.0, 3.0)]
    cold = _run(tmp_path, device)
    np.testing.assert_allclose(cold["grad"], expected, rtol=1e-5)
    assert cold["built"] == ["k", "k", "k"]  # the kernel, its adjoint and its tape counter
    assert cold["index"]["stored"] == 3
    warm = _run(tmp_path, device)
    np.testing.assert_allclose(warm["grad"], expected, rtol=1e-5)
    assert warm["built"] == [] and warm["parsed"] == [] and warm["kernel_builds"] == 0
    assert warm["index"]["hits"] == 3
    _edit(tmp_path / "kern.py", "SCALE = 2.0", "SCALE = 5.0")
    edited = _run(tmp_path, device)
    np.testing.assert_allclose(edited["grad"], [_gradient(x, 5.0) for x in (1.0, 2.0, 3.0)],
                               rtol=1e-5)  # fmt: skip
    assert edited["built"] == ["k", "k", "k"] and edited["index"]["misses"] == 3
