"""Where a warm compile (a kernel cache hit in a fresh process) spends its time, by phase.

    python benchmarks/profile_warm_compile.py [--device cpu|cuda:0] [--reps 5]
                                              [--kernels nbody,spring,scenes] [--cprofile]

Each sample is a fresh Python process over a kernel cache that already holds the
kernels (filled by a first process, plus one more run to write bytecode and load the
backend's support code once). The child runs bench_cuda's warm-compile script as it is
(``suite.kdsl_impl.START_SCRIPT``: the n-body module, first launch to first result),
or the spring-chain kernel of ``bench_warm_compile.py``, or the first step of every
scene (``kdsl.scenes``: their kernels' first launches), with timers wrapped around
the functions of the warm path (``time.perf_counter``, inclusive, summed over calls;
``--clock thread``: ``time.thread_time``, the CPU time of the thread, which a loaded
host does not inflate, though it leaves out waiting for the disk or the GPU):

- ``launch (first)``: the first ``kdsl.launch`` of each kernel, everything included;
- ``source parse``: reading and parsing kernels' and functions' sources (``inspect``,
  ``ast``), wherever it happens;
- ``backend import``: resolving the backend (importing its modules) at the first launch;
- ``compile_kernel``: the compile driver, of which ``source memo`` (the recorded facts
  of the kernel's sources, ``source_index.load_memo``), ``fingerprint`` (the kernel's
  source digest), ``source key`` (the index key around it), ``index read`` (the
  ``.kidx`` entry read and checked), ``unpickle`` (the module restored),
  ``backend.load``, of which ``kernel key`` (the IR key, a sha256 of the IR text),
  ``binary read`` (the ``.kobj`` entry read and checked) and ``binary load``
  (``dlopen`` on cpu, ``cuModuleLoadData`` on cuda);
- ``support``: the backend's support code (the cpu thread pool), once per process;
- ``backend.launch``: the launch itself (packing the parameters, the kernel's run);
- ``sync``: reading the result back (``array.numpy``);
- ``gc (gen N)``: the garbage collections that ran inside first launches (whichever
  phase above they landed in): a generation-1 collection traverses the objects created
  since the last one (most of ``import kdsl``'s), 2 to 5 ms here, and lands in the
  first launch or after it depending on how many objects each phase allocated.

On cuda the cubin is read in ``backend.load`` but loaded (``binary load``) at the first
launch, inside ``backend.launch``. ``--no-bytecode`` runs a copy of kdsl without
``__pycache__`` under ``PYTHONDONTWRITEBYTECODE=1`` (what a fresh checkout run that way
pays: every lazily imported module compiled from source); ``--repo DIR`` profiles
another checkout with this script, and ``--against DIR`` profiles a second one in the
same run, the two trees' processes interleaved (before/after columns on a noisy host).

Medians over ``--reps`` processes; ``--cprofile`` also prints the top of a cProfile
of one warm process. JSON in benchmarks/results/warm_compile_phases.json.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_warm_compile import KERNEL
from suite.harness import print_table, save_json, script_meta, script_parser
from suite.kdsl_impl import START_SCRIPT
from suite.workloads import START_BODIES

RESULTS = Path(__file__).resolve().parent / "results" / "warm_compile_phases.json"
REPO = Path(__file__).resolve().parents[1]

#: Installed in the child before its kernels are defined: wraps the warm path's
#: functions with inclusive timers and prints them (JSON, last line) at exit.
TIMERS = r"""
import atexit, json, os, time, sys
import kdsl
from kdsl.compiler import cache as _cache, driver as _driver, source_index as _index
from kdsl.frontend import kernel as _kernel
from kdsl.runtime import launch as _launch, array as _array

PHASES = {}
CLOCK = time.thread_time if os.environ.get("KDSL_PHASE_CLOCK") == "thread" else time.perf_counter
_DEPTH = {}

def _wrap(owner, attr, name, pick=None):
    fn = getattr(owner, attr, None)
    if fn is None:  # not in this version of kdsl
        return
    def timed(*a, **k):
        label = name if pick is None else pick(*a, **k)
        if label is None or _DEPTH.get(label):
            return fn(*a, **k)
        _DEPTH[label] = 1
        t = CLOCK()
        try:
            return fn(*a, **k)
        finally:
            PHASES[label] = PHASES.get(label, 0.0) + CLOCK() - t
            _DEPTH[label] = 0
    setattr(owner, attr, timed)

_wrap(_launch, "_resolve_backend", "backend import")
_wrap(_launch, "compile_kernel", "compile_kernel")
_wrap(_launch, "load_support", "support")
_wrap(_kernel, "source_fingerprint", "fingerprint")
_wrap(_kernel, "ParsedSource", "source parse")
_wrap(_index, "load_memo", "source memo")
_wrap(_index, "source_key", "source key")
_wrap(_cache.DiskCache, "load", None,
      lambda self, key: "index read" if self.suffix == _cache.INDEX_SUFFIX else "binary read")
_wrap(_index._Unpickler, "load", "unpickle")
_wrap(_cache, "kernel_key", "kernel key")
_wrap(_array.array, "numpy", "sync")

def _backend_hooks(backend):
    cls = type(backend)
    if getattr(cls, "_timed", False):
        return
    cls._timed = True
    _wrap(cls, "load", "backend.load")
    _wrap(cls, "launch", "backend.launch")
    _wrap(cls, "code_version", "code version")
    mod = sys.modules[cls.__module__]
    if backend.name == "cuda":
        _wrap(mod.CudaKernel, "function", "binary load")
        _wrap(mod, "current_arch", "target")
        _wrap(mod.nvrtc, "cache_name", "toolchain name")
        _wrap(mod, "fast_plan", "launch facts")
        _wrap(mod, "Packer", "launch facts")
    else:
        _wrap(cls, "load_artifact", "binary load")
        _wrap(mod.host, "target_id", "target")

_plan = _launch._Plan.__init__
def _plan_init(self, kernel, device, backend, *rest):
    _backend_hooks(backend)
    return _plan(self, kernel, device, backend, *rest)
_launch._Plan.__init__ = _plan_init

_first = set()
_in_first = [False]
_real_launch = _launch.launch
def _timed_launch(kernel, *a, **k):
    if id(kernel) in _first:
        return _real_launch(kernel, *a, **k)
    _first.add(id(kernel))
    t = CLOCK()
    _in_first[0] = True
    try:
        return _real_launch(kernel, *a, **k)
    finally:
        _in_first[0] = False
        PHASES["launch (first)"] = PHASES.get("launch (first)", 0.0) + CLOCK() - t
kdsl.launch = _timed_launch

import gc
_gc_start = [0.0]
def _gc_timer(phase, info):  # collections inside first launches, whichever phase pays
    if not _in_first[0]:
        return
    if phase == "start":
        _gc_start[0] = CLOCK()
    else:
        label = "gc (gen %d)" % min(info["generation"], 1) if info["generation"] < 2 else "gc (gen 2)"
        PHASES[label] = PHASES.get(label, 0.0) + CLOCK() - _gc_start[0]
gc.callbacks.append(_gc_timer)
kdsl.launch = _timed_launch

@atexit.register
def _report():
    from kdsl.compiler import source_index, cache
    print(json.dumps({"phases": PHASES, "index_hits": source_index.STATS.hits,
                      "builds": cache.STATS.builds, "disk_hits": cache.STATS.disk_hits}))
"""

#: bench_warm_compile's spring-chain kernel, launched once.
SPRING = (
    KERNEL
    + """
import numpy as np

n = 256
x = wp.from_numpy(np.arange(3 * n, dtype=np.float32).reshape(n, 3), dtype=wp.vec3,
                  device="{device}")
v = wp.zeros(n, dtype=wp.vec3, device="{device}")
wp.launch(step, dim=n, inputs=[x, v, 0.01], device="{device}")
x.numpy()
"""
)

SCENES = """
import kdsl
from bench_scenes import SIZES
from kdsl.scenes.measure import make_scene
for name, (integrator, params, dt, _) in SIZES.items():
    scene = make_scene(name, "f32", integrator, "{device}")  # the scene's default size
    scene.step(dt)
    scene.wp.synchronize_device(scene.device)
"""

ROWS = (
    "launch (first)", "source parse", "backend import", "compile_kernel", "source memo",
    "fingerprint", "source key", "code version", "index read", "unpickle", "backend.load",
    "target", "toolchain name", "kernel key", "binary read", "binary load", "launch facts",
    "support", "backend.launch", "sync", "gc (gen 0)", "gc (gen 1)", "gc (gen 2)",
)  # fmt: skip
INDENT = {
    "source memo": 1, "fingerprint": 1, "source key": 1, "code version": 2, "index read": 1,
    "unpickle": 1, "backend.load": 1, "target": 2, "toolchain name": 2, "kernel key": 2,
    "binary read": 2, "binary load": 2, "launch facts": 2,
}  # fmt: skip


def _script(kind: str, device: str) -> str:
    if kind == "nbody":
        body = START_SCRIPT.format(bodies=START_BODIES, device=device)
    elif kind == "spring":
        body = SPRING.replace("{device}", device)
    else:
        body = SCENES.replace("{device}", device.split(":")[0])
    return TIMERS + body


def _run(workdir: Path, name: str, env: dict[str, str]) -> dict:
    proc = subprocess.run([sys.executable, str(workdir / name)], cwd=workdir, env=env,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr.strip()[-2000:] or "failed")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _tree_env(work: Path, label: str, repo: Path, no_bytecode: bool) -> dict[str, str]:
    """The environment of the processes profiling the kdsl checkout ``repo``."""
    env = {**os.environ, "KDSL_CACHE_DIR": str(work / f"cache-{label}")}
    if no_bytecode:  # a tree without __pycache__ that nothing writes bytecode for
        shutil.copytree(repo / "kdsl", work / f"tree-{label}" / "kdsl",
                        ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        root = work / f"tree-{label}"
    else:
        env.pop("PYTHONDONTWRITEBYTECODE", None)  # as users run: bytecode cached
        root = repo
    paths = [str(root), str(REPO / "benchmarks"),
             *filter(None, env.get("PYTHONPATH", "").split(os.pathsep))]  # fmt: skip
    env["PYTHONPATH"] = os.pathsep.join(paths)
    env["CUDA_CACHE_PATH"] = str(work / f"cuda-jit-cache-{label}")
    return env


def main() -> int:
    """Fill a cache, time warm processes, print the phases."""
    p = script_parser(__doc__, RESULTS, reps=5)
    p.add_argument("--device", default="cpu", help="cpu or cuda:N")
    p.add_argument("--kernels", default="nbody,spring", help="nbody, spring, scenes")
    p.add_argument("--cprofile", action="store_true", help="print a cProfile of one warm run")
    p.add_argument(
        "--no-bytecode", action="store_true",
        help="kdsl copied without __pycache__ and PYTHONDONTWRITEBYTECODE=1 (every "
        "module compiled from source in every process)",
    )  # fmt: skip
    p.add_argument("--clock", choices=("wall", "thread"), default="wall",
                   help="wall: time.perf_counter; thread: time.thread_time (CPU time)")  # fmt: skip
    p.add_argument("--repo", default="", help="the kdsl checkout to profile (default: this one)")
    p.add_argument("--against", default="",
                   help="another checkout (e.g. a worktree of an older commit), profiled "
                        "in the same run, processes interleaved: columns 'before'")  # fmt: skip
    args = p.parse_args()
    kinds = [k for k in args.kernels.split(",") if k]
    trees = [("after" if args.against else "", Path(args.repo).resolve() if args.repo else REPO)]
    if args.against:
        trees.insert(0, ("before", Path(args.against).resolve()))
    data: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="kdsl-phases-") as tmp:
        work = Path(tmp)
        envs = {label: _tree_env(work, label or "this", repo, args.no_bytecode)
                for label, repo in trees}  # fmt: skip
        for env in envs.values():
            env["KDSL_PHASE_CLOCK"] = args.clock
        for kind in kinds:
            name = f"warm_{kind}.py"
            (work / name).write_text(_script(kind, args.device))
            cols = {label: f"{kind} {label}".strip() for label in envs}
            cold = {label: _run(work, name, env) for label, env in envs.items()}
            for env in envs.values():
                _run(work, name, env)  # bytecode written, support code cached
            samples: dict[str, dict[str, list[float]]] = {c: {} for c in cols.values()}
            last: dict[str, dict] = {}
            for _ in range(args.reps):
                for label, env in envs.items():  # interleaved: the same load for both
                    got = last[label] = _run(work, name, env)
                    for row in ROWS:
                        samples[cols[label]].setdefault(row, []).append(got["phases"].get(row, 0.0))
            for label, col in cols.items():
                data[col] = {"samples_s": samples[col], "cold_builds": cold[label]["builds"],
                             "warm_builds": last[label]["builds"],
                             "index_hits": last[label]["index_hits"]}  # fmt: skip
            if args.cprofile:
                proc = subprocess.run(
                    [sys.executable, "-m", "cProfile", "-s", "cumulative", name], cwd=work,
                    env=envs[trees[-1][0]], capture_output=True, text=True, timeout=300,
                )  # fmt: skip
                print(f"--- cProfile of a warm {kind} process (top 40) ---")
                print("\n".join(proc.stdout.splitlines()[:48]))
    headers = ["phase [ms]", *data]
    rows = []
    for row in ROWS:
        cells = [f"{statistics.median(d['samples_s'][row]) * 1e3:.2f}" for d in data.values()]
        rows.append(["  " * INDENT.get(row, 0) + row, *cells])
    code = "no bytecode" if args.no_bytecode else "bytecode cached"
    clock = "CPU" if args.clock == "thread" else "wall"
    print(f"warm compile phases on {args.device} ({code}): medians of {args.reps} fresh "
          f"processes, inclusive {clock} times [ms]")  # fmt: skip
    if args.against:
        print(f"before: {trees[0][1]}; after: {trees[1][1]}")
    print_table(headers, rows)
    for col, d in data.items():
        print(f"{col}: warm builds {d['warm_builds']} (must be 0), index hits {d['index_hits']}")
    meta = {**script_meta("profile_warm_compile.py"), "device": args.device,
            "bytecode": not args.no_bytecode, "clock": args.clock, "trees": {k: str(v) for k, v in trees},
            "time": time.strftime("%Y-%m-%d %H:%M:%S")}  # fmt: skip
    save_json({"meta": meta, "results": data}, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
