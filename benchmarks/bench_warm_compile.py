"""Warm compile and warm start with and without the kernel cache's source index.

    python benchmarks/bench_warm_compile.py [--device cpu|cuda:0] [--arch sm_90] [--reps 7]

Each sample is a fresh Python process over a kernel cache that already holds the
kernel (a spring-chain step calling a ``@kdsl.func`` and reading a constant), run
twice per repetition, once with
the source index (``kdsl.compiler.source_index``: the default) and once with it off
(``KDSL_SOURCE_INDEX=0``: the kernel keyed by its optimized IR, so the frontend and
the passes run first), the two interleaved. Rows:

- ``compile_kernel (hit)``: the driver's ``compile_kernel`` of the kernel, after
  ``import kdsl`` and the backend's import (the cache hit itself);
- ``first launch (hit)``: the first ``kdsl.launch`` and a synchronization, compile
  included (bench_cuda's "warm compile"); ``--arch`` without a GPU skips it;
- ``import to first result``: ``import kdsl`` to the first launch's result;
- ``cold compile_kernel``: the same, in the process that filled the cache (a miss).

Also printed: whether a hit imported llvmlite's binding or a pass module. Medians of
``--reps``; JSON in benchmarks/results/warm_compile.json.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from suite.harness import print_table, save_json, script_meta, script_parser

RESULTS = Path(__file__).resolve().parent / "results" / "warm_compile.json"
REPO = Path(__file__).resolve().parents[1]

KERNEL = """\
import kdsl as wp

GRAVITY = wp.constant(9.8)


@wp.func
def spring(d: wp.vec3, stiffness: float):
    n = wp.length(d)
    return d * (stiffness * (n - 1.0) / wp.max(n, 1.0e-6))


@wp.kernel
def step(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), dt: float):
    i = wp.tid()
    f = wp.vec3(0.0, -GRAVITY, 0.0)
    if i > 0:
        f = f - spring(x[i] - x[i - 1], 50.0)
    v[i] = v[i] + f * dt
    x[i] = x[i] + v[i] * dt
"""

CHILD = """\
import json, sys, time
t0 = time.perf_counter()
import kdsl as wp
t1 = time.perf_counter()
import numpy as np
from kdsl import config
from kdsl.backends.registry import get_backend
from kdsl.compiler import compile_kernel, source_index
from kdsl.runtime.launch import default_backend_for
from kdsl.runtime.modules import kernel_options
from kern import step

mode, device, arch = sys.argv[1], sys.argv[2], sys.argv[3]
backend = get_backend("cuda" if arch else default_backend_for(device))
backend.code_version()
if device.startswith("cuda") and not arch:
    wp.zeros(1, device=device)  # CuPy imported and the context made, as before a launch
before = set(sys.modules)
t2 = time.perf_counter()
if mode == "compile":
    opts = config.compile_options(kernel_options(step))
    if arch:
        opts["arch"] = arch
    compiled = compile_kernel(backend, step, options=opts)
    if arch:
        compiled.payload.cubin(arch)
else:
    n = 256
    x = wp.from_numpy(np.arange(3 * n, dtype=np.float32).reshape(n, 3), dtype=wp.vec3,
                      device=device)
    v = wp.zeros(n, dtype=wp.vec3, device=device)
    t2 = time.perf_counter()
    wp.launch(step, dim=n, inputs=[x, v, 0.01], device=device)
    x.numpy()
t3 = time.perf_counter()
new = set(sys.modules) - before
print(json.dumps({
    "import_s": t1 - t0, "step_s": t3 - t2, "to_result_s": t3 - t1,
    "index_hits": source_index.STATS.hits,
    "llvmlite_binding": "llvmlite.binding" in new,
    "pass_modules": sorted(m for m in new if m.startswith("kdsl.passes.")),
}))
"""


def _run(workdir: Path, cache: Path, mode: str, device: str, arch: str, index: bool) -> dict:
    env = {**os.environ, "KDSL_CACHE_DIR": str(cache), "KDSL_SOURCE_INDEX": "1" if index else "0"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as users run: bytecode cached
    paths = [str(workdir), str(REPO), *filter(None, env.get("PYTHONPATH", "").split(os.pathsep))]
    env["PYTHONPATH"] = os.pathsep.join(paths)
    proc = subprocess.run([sys.executable, str(workdir / "child.py"), mode, device, arch],
                          cwd=workdir, env=env, capture_output=True, text=True, timeout=300)  # fmt: skip
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr.strip().splitlines()[-1] if proc.stderr else "failed")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> int:
    """Run the processes, print the table, write JSON."""
    p = script_parser(__doc__, RESULTS, reps=7)
    p.add_argument("--device", default="cpu", help="cpu or cuda:N")
    p.add_argument("--arch", default="", help="compile-only cuda for this arch (no GPU needed)")
    args = p.parse_args()
    launch = not args.arch
    samples: dict[tuple[str, bool], list[float]] = {}
    notes: dict[bool, dict] = {}
    with tempfile.TemporaryDirectory(prefix="kdsl-warm-") as tmp:
        work = Path(tmp)
        (work / "kern.py").write_text(KERNEL)
        (work / "child.py").write_text(CHILD)
        caches = {True: work / "cache-index", False: work / "cache-ir"}
        # A throwaway cold compile first: the first process of a run also pays for cold
        # OS file caches (libraries, NVRTC), which the cold row must not charge to one side.
        _run(work, work / "cache-throwaway", "compile", args.device, args.arch, False)
        for index in (True, False):
            cold = _run(work, caches[index], "compile", args.device, args.arch, index)
            samples[("cold compile_kernel", index)] = [cold["step_s"]]
            # Bytecode files, and the backend's support code (the cpu thread pool).
            _run(work, caches[index], "launch" if launch else "compile", args.device,
                 args.arch, index)  # fmt: skip
        for _ in range(args.reps):
            for index in (True, False):
                hit = _run(work, caches[index], "compile", args.device, args.arch, index)
                samples.setdefault(("compile_kernel (hit)", index), []).append(hit["step_s"])
                notes[index] = hit
                if launch:
                    first = _run(work, caches[index], "launch", args.device, args.arch, index)
                    samples.setdefault(("first launch (hit)", index), []).append(first["step_s"])
                    samples.setdefault(("import to first result", index), []).append(
                        first["to_result_s"]
                    )
    rows, data = [], {}
    order = ["compile_kernel (hit)", "first launch (hit)", "import to first result",
             "cold compile_kernel"]  # fmt: skip
    for name in order:
        if (name, True) not in samples:
            continue
        on, off = (statistics.median(samples[(name, i)]) * 1e3 for i in (True, False))
        rows.append([name, f"{off:.2f}", f"{on:.2f}", f"{off / on:.1f}x"])
        data[name] = {"ir_key_ms": samples[(name, False)], "source_index_ms": samples[(name, True)]}
    target = args.arch or args.device
    print(f"warm compile, {target}: medians of {args.reps} fresh processes [ms]")
    print_table(["row", "IR key only", "source index", "speed-up"], rows)
    hit = notes[True]
    print(f"a hit imported llvmlite.binding: {hit['llvmlite_binding']}; pass modules: "
          f"{hit['pass_modules'] or 'none'}; index hits: {hit['index_hits']}")  # fmt: skip
    meta = {**script_meta("bench_warm_compile.py"), "device": target,
            "time": time.strftime("%Y-%m-%d %H:%M:%S")}  # fmt: skip
    save_json({"meta": meta, "results": data}, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
