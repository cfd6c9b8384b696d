"""The all-pairs n-body kernel with and without the ``block-cache`` tiling, and what its
IEEE build costs.

On a CUDA GPU, for several body counts, the n-body kernel of ``suite/kdsl_impl.py``
(IEEE and fast math) is timed as the cuda backend compiles it (``block-cache`` in its
pipeline: the loop over bodies reads shared-memory tiles) and compiled without that
pass (the plain loop). The two builds' accelerations are compared first: bit for bit
in IEEE builds, to 1e-6 in fast-math ones. The time per launch is the median over
samples of back-to-back launches (``suite.harness.measure_device``).

``--compile-only`` (no GPU needed) compiles the generated CUDA C, tiled and plain,
with NVRTC for ``sm_90`` under kdsl's IEEE options, its fast-math option and the
IEEE options with one relaxation each (FMA contraction, approximate division,
approximate square root, flushing subnormals), and prints the PTX instruction counts
of the floating-point division, square root, reciprocal, FMA and load instructions:
the static side of the IEEE row's cost. Where ``nvdisasm`` is on the PATH (the
``nvidia-cuda-nvdisasm`` wheel has it; kdsl does not need it), it also disassembles
each build and prints the SASS instructions per interaction of the hot loop (the
innermost loop holding the most square roots: the unrolled body).

    PYTHONPATH=. python benchmarks/bench_nbody_tiles.py               # a CUDA GPU
    python benchmarks/bench_nbody_tiles.py --compile-only              # NVRTC only
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from suite import harness
from suite import kdsl_impl as K
from suite import workloads as W

import kdsl as wp
from kdsl.backends.cuda import BACKEND as CUDA
from kdsl.backends.cuda import nvrtc
from kdsl.compiler import lower
from kdsl.passes import DEFAULT_PIPELINE

RESULTS = Path(__file__).resolve().parent / "results"
BODIES = (4096, 16384, 65536)
ARCH = "sm_90"
#: NVRTC option sets of ``--compile-only``: kdsl's two, and IEEE with one relaxation.
IEEE = ["--ftz=false", "--prec-div=true", "--prec-sqrt=true", "--fmad=false"]
FLAG_SETS = {
    "ieee (kdsl)": IEEE,
    "ieee + fmad": [*IEEE[:3], "--fmad=true"],
    "ieee + approx div": [IEEE[0], "--prec-div=false", *IEEE[2:]],
    "ieee + approx sqrt": [*IEEE[:2], "--prec-sqrt=false", IEEE[3]],
    "ieee + ftz": ["--ftz=true", *IEEE[1:]],
    "ftz, approx div/sqrt, no fmad": [
        "--ftz=true",
        "--prec-div=false",
        "--prec-sqrt=false",
        "--fmad=false",
    ],
    "fast math (kdsl)": ["--use_fast_math"],
}
COUNTED = ("div", "sqrt", "rsqrt", "rcp", "fma", "ld.global", "ld.shared", "bar.sync")


@contextmanager
def plain_pipeline() -> Iterator[None]:
    """Compile cuda kernels without ``block-cache`` while inside (the plain loop)."""
    CUDA.pipeline = DEFAULT_PIPELINE  # an instance attribute over the class's
    try:
        yield
    finally:
        del CUDA.pipeline


def _kernels(fast: bool) -> tuple[wp.Kernel, wp.Kernel]:
    """(tiled, plain) n-body kernels: two kernel objects, so each compiles once."""
    opts = {"fast_math": True} if fast else {}
    fn = K.nbody_kernel.func
    return wp.kernel(**opts)(fn), wp.kernel(**opts)(fn)


def ptx_counts(ptx: str) -> Counter:
    """Counts of the ``COUNTED`` instruction families in ``ptx``."""
    out: Counter = Counter()
    for line in ptx.splitlines():
        m = re.match(r"\s*(?:@%?!?\w+\s+)?([a-z][\w.]*)", line)
        if not m or line.strip().startswith(("//", ".")):
            continue
        ins = m.group(1)
        for fam in COUNTED:
            if ins == fam or ins.startswith(fam + "."):
                out[fam] += 1
    return out


def compile_only() -> int:
    tiled_k, plain_k = _kernels(False)
    tiled = lower(CUDA, tiled_k, "cuda-c")
    with plain_pipeline():
        plain = lower(CUDA, plain_k, "cuda-c")
    disasm = shutil.which("nvdisasm")
    print(f"PTX instruction counts of the n-body kernel (NVRTC {nvrtc.version()}, {ARCH})")
    rows = []
    for name, flags in FLAG_SETS.items():
        for loop, src in (("tiled", tiled), ("plain", plain)):
            opts = [f"--gpu-architecture={ARCH}", "--std=c++17", *flags]
            ptx, cubin = _build(src, opts)
            c = ptx_counts(ptx)
            approx = len(re.findall(r"\.approx", ptx))
            per = f"{sass_per_interaction(disasm, cubin):.1f}" if disasm else "-"
            rows.append([name, loop, *(str(c[f]) for f in COUNTED), str(approx), per])
    harness.print_table(["NVRTC options", "loop", *COUNTED, ".approx", "SASS/pair"], rows)
    return 0


def _build(src: str, opts: list[str]) -> tuple[str, bytes]:
    """PTX and cubin of ``src`` (CuPy's NVRTC binding, as the backend compiles)."""
    from cupy_backends.cuda.libs import nvrtc as lib

    prog = lib.createProgram(src, "nbody.cu", [], [])
    try:
        lib.compileProgram(prog, opts)
        ptx = lib.getPTX(prog)
        # CuPy returns the cubin without its last byte (a NUL pad): the driver loads it
        # as is, nvdisasm wants the whole ELF.
        cubin = bytes(lib.getCUBIN(prog)) + b"\0"
    finally:
        lib.destroyProgram(prog)
    return (ptx.decode() if isinstance(ptx, bytes) else ptx).rstrip("\0"), cubin


def sass_per_interaction(disasm: str, cubin: bytes) -> float:
    """SASS instructions per body pair in the innermost loop with the most square roots."""
    with tempfile.NamedTemporaryFile(suffix=".cubin") as f:
        f.write(cubin)
        f.flush()
        text = subprocess.run([disasm, "-c", f.name], capture_output=True, text=True).stdout
    labels: dict[str, int] = {}
    ins: list[str] = []
    for line in text.splitlines():
        if m := re.match(r"^(\.L_x_\d+):", line):
            labels[m.group(1)] = len(ins)
        elif re.match(r"\s+/\*[0-9a-f]{4}\*/", line):
            ins.append(line.split("*/", 1)[1].split(";")[0])
    loops = [(labels[m.group(1)], i) for i, t in enumerate(ins)
             if (m := re.search(r"BRA `\((\.L_x_\d+)\)", t)) and labels.get(m.group(1), i + 1) <= i]  # fmt: skip
    best = (0, 0.0)
    for a, b in loops:
        if any(a <= c and d <= b and (c, d) != (a, b) for c, d in loops):
            continue  # not innermost
        body = ins[a : b + 1]
        roots = sum("MUFU.RSQ" in t or "MUFU.SQRT" in t for t in body)
        if roots > best[0]:
            best = (roots, len(body) / roots)
    return best[1]


def _run(kernel: wp.Kernel, ins: dict, device: str) -> tuple[np.ndarray, harness.Stats]:
    n = len(ins["pos"])
    pos = wp.array(ins["pos"], dtype=wp.vec3, device=device)
    mass = wp.array(ins["mass"], device=device)
    acc = wp.zeros(n, dtype=wp.vec3, device=device)
    args = [pos, mass, acc, ins["eps2"]]

    def step() -> None:
        wp.launch(kernel, dim=n, inputs=args, device=device)

    dev = wp.get_device(device)
    sync = (lambda: None) if dev.is_cpu else wp.get_stream(device).synchronize
    stats, _ = harness.measure_device(step, sync, reps=15)
    return acc.numpy(), stats


def on_gpu(device: str, bodies: list[int]) -> int:
    rng = np.random.default_rng(0)
    rows, data = [], {"machine": harness.machine(), "device": wp.get_device(device).name,
                      "rows": []}  # fmt: skip
    failed = False
    for fast in (False, True):
        tiled_k, plain_k = _kernels(fast)
        for n in bodies:
            ins = W.nbody_inputs(n, rng)
            got_t, t_tiled = _run(tiled_k, ins, device)
            with plain_pipeline():
                got_p, t_plain = _run(plain_k, ins, device)
            if fast:
                same = bool(np.allclose(got_t, got_p, rtol=1e-6, atol=1e-6))
            else:
                same = bool((got_t.view(np.uint32) == got_p.view(np.uint32)).all())
            failed |= not same
            label = "fast math" if fast else "IEEE"
            ms_t, ms_p = t_tiled.median * 1e3, t_plain.median * 1e3
            rows.append([label, str(n), f"{ms_p:.3g}", f"{ms_t:.3g}", f"{ms_p / ms_t:.2f}x",
                         "yes" if same else "NO"])  # fmt: skip
            data["rows"].append({"math": label, "bodies": n, "plain_ms": ms_p, "tiled_ms": ms_t,
                                 "same_results": same, "plain_samples": t_plain.samples,
                                 "tiled_samples": t_tiled.samples})  # fmt: skip
    print(f"n-body on {data['device']}: plain loop against block-cache tiles (ms per launch)")
    harness.print_table(["math", "bodies", "plain", "tiled", "speed-up", "same results"], rows)
    path = RESULTS / f"nbody-tiles-{time.strftime('%Y%m%d-%H%M%S')}.json"
    harness.save_json(data, path)
    return 1 if failed else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--compile-only", action="store_true", help="NVRTC PTX counts, no GPU")
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--bodies", default=",".join(map(str, BODIES)), help="comma list")
    args = p.parse_args()
    if args.compile_only:
        return compile_only()
    if not wp.is_cuda_available():
        print("bench_nbody_tiles: no CUDA device; try --compile-only", file=sys.stderr)
        return 1
    return on_gpu(args.device, [int(b) for b in args.bodies.split(",")])


if __name__ == "__main__":
    sys.exit(main())
