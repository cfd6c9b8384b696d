"""Where kdsl's Jacobi and cloth kernels lose time on a GPU: device time of variants.

``bench_cuda.py`` times back-to-back plain launches, so a short kernel (the 256^2
cloth step, a few microseconds of GPU work) measures the host's launch path as much
as the kernel. This script separates the two and attributes the kernel's own time:

- every variant is launched ``--per-graph`` times inside one CUDA graph (CuPy's
  stream capture), the graph is replayed, and the time per kernel is the replay time
  divided by the launch count (CUDA events): device time, no host launch cost;
- the variants are the hand-written kernels of ``suite/cupy_impl.py``, a hand-written
  Jacobi over 1-d blocks with a division per thread (kdsl's thread mapping), and
  kdsl's own generated CUDA C (``kdsl ir --stage cuda-c``) as is and with one change
  each: ``narrow`` addresses (32x32->64-bit products, exact while every stride fits in
  int32), ``ldg`` (the arrays the kernel only reads loaded through ``__ldg``), ``div``
  (cloth's ``tid // grid`` as C's ``/``: exact for non-negative operands), ``rows``
  (Jacobi: a 2-d grid of 256-thread rows instead of a division per thread);
- kdsl's fast entry as generated (32-bit offsets, ``__ldg`` on the arrays it only
  reads and, for Jacobi, a 2-d grid of rows: ``kdsl/backends/cuda/variants.py``);
- kdsl's own launches of the same kernels: plain ``wp.launch`` back to back, a
  prepared launch (``record_cmd=True``) and a ``wp.ScopedCapture`` graph replay
  (these take the fast entry whenever the launch-time checks allow).

The kdsl variants run through a shim kernel that builds kdsl's array descriptors
from pointers, extents and strides passed as 64-bit parameters (opaque to NVRTC, as
they are to kdsl's own launch). Every variant's output is compared with the float64
NumPy reference of ``suite/workloads.py`` before it is timed.

    PYTHONPATH=. python benchmarks/bench_stencil_variants.py          # a CUDA GPU
    python benchmarks/bench_stencil_variants.py --compile-only        # NVRTC only

``--compile-only`` (no GPU needed) builds every variant's source with NVRTC for
``sm_90`` and prints the PTX instruction counts of the 64-bit multiplies, divisions
and loads per variant; with ``--nvdisasm PATH`` (and ``ptxas`` on PATH) also the
SASS counts: the static side of the same comparison.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from suite import kdsl_impl as K
from suite import workloads as W

import kdsl as wp
from kdsl.backends.cuda import BACKEND as CUDA
from kdsl.backends.cuda import nvrtc
from kdsl.backends.cuda.lower import fast_entry_name
from kdsl.compiler import lower

SHIM_JACOBI = r"""
extern "C" __global__ void __launch_bounds__(256) shim(
    char *u, char *out, long long rows, long long cols, long long s0, long long s1,
    unsigned int n, unsigned int d0, unsigned int d1) {
  kd_array2 a{u, {rows, cols}, {s0, s1}};
  kd_array2 b{out, {rows, cols}, {s0, s1}};
  kd_grid g{n, {d0, d1, 1u, 1u}};
  ENTRY(a, b, g);
}
"""

SHIM_CLOTH = r"""
extern "C" __global__ void __launch_bounds__(256) shim(
    char *x, char *v, char *x_out, char *v_out, long long n, long long s, int grid,
    float spacing, float k, float inv_mass, float gx, float gy, float gz, float dt,
    unsigned int threads) {
  kd_array1 a{x, {n}, {s}}, b{v, {n}, {s}}, c{x_out, {n}, {s}}, d{v_out, {n}, {s}};
  kd_vec3_f32 g{{gx, gy, gz}};
  kd_grid kg{threads, {threads, 1u, 1u, 1u}};
  ENTRY(a, b, c, d, grid, spacing, k, inv_mass, g, dt, kg);
}
"""

#: Jacobi over 1-d blocks with a division per thread: kdsl's thread mapping, by hand.
HAND_1D = r"""
extern "C" __global__ void jacobi_1d(const float* __restrict__ u, float* __restrict__ out,
                                     int rows, int cols) {
  unsigned int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= (unsigned int)(rows * cols)) return;
  int r = i / cols, c = i % cols;
  int k = r * cols + c;
  if (r == 0 || c == 0 || r == rows - 1 || c == cols - 1)
    out[k] = u[k];
  else
    out[k] = 0.25f * (u[k - cols] + u[k + cols] + u[k - 1] + u[k + 1]);
}
"""

_LDG3 = (
    "__device__ __forceinline__ kd_vec3_f32 kd_ldg3(const float *p) "
    "{ return kd_vec3_f32{{__ldg(p), __ldg(p + 1), __ldg(p + 2)}}; }\n"
)


def kdsl_source(kernel: Any) -> tuple[str, str]:
    """kdsl's CUDA C unit for ``kernel`` (``#line`` directives dropped) and its entry."""
    text = lower(CUDA, kernel, "cuda-c")
    text = "\n".join(ln for ln in text.splitlines() if not ln.startswith("#line"))
    return text, _symbol(text)


def _symbol(text: str) -> str:
    m = re.search(r"__global__ void __launch_bounds__\(\d+\) (\w+)\(", text)
    if m is None:
        raise RuntimeError("no kernel entry in kdsl's CUDA C")
    return m.group(1)


def as_device_function(text: str, entry: str, shim: str) -> str:
    """``text`` with kdsl's kernel turned into a device function the shim calls."""
    head = re.compile(r'extern "C" __global__ void __launch_bounds__\(\d+\) ' + entry + r"\(")
    if not head.search(text):
        raise RuntimeError(f"kernel {entry} not found")
    text = head.sub(f"__device__ __forceinline__ void {entry}(", text)
    return text + shim.replace("ENTRY", entry)


def narrow(text: str) -> str:
    """Addresses as 32x32->64-bit products (exact while each stride fits in int32)."""
    pattern = re.compile(
        r"(char \*kd_at\d\(const kd_array\d &a, [^)]*\) \{ return a\.data \+ )([^;]*);"
    )

    def sub(m: re.Match) -> str:
        terms = re.findall(r"i(\d) \* a\.strides\[(\d)\]", m.group(2))
        narrow_terms = " + ".join(f"(long long)(int)i{i} * (int)a.strides[{k}]" for i, k in terms)
        return m.group(1) + narrow_terms + ";"

    out, count = pattern.subn(sub, text)
    if not count:
        raise RuntimeError("no kd_at accessor to narrow")
    return out


def offsets32(text: str) -> str:
    """Byte offsets summed in 32 bits, widened once (exact while every array's byte
    size fits in int32: the guard a launch would check)."""
    pattern = re.compile(
        r"(char \*kd_at\d\(const kd_array\d &a, [^)]*\) \{ return a\.data \+ )([^;]*);"
    )

    def sub(m: re.Match) -> str:
        terms = re.findall(r"i(\d) \* a\.strides\[(\d)\]", m.group(2))
        total = " + ".join(f"(int)i{i} * (int)a.strides[{k}]" for i, k in terms)
        return m.group(1) + f"(long long)({total});"

    out, count = pattern.subn(sub, text)
    if not count:
        raise RuntimeError("no kd_at accessor to narrow")
    return out


def ldg(text: str, read_only: list[str]) -> str:
    """Loads from the parameters ``read_only`` through ``__ldg`` (float and vec3)."""
    for name in read_only:
        text = re.sub(
            r"\*\(const float \*\)(kd_at\d\(" + name + r", [^)]*\))",
            r"__ldg((const float *)\1)",
            text,
        )
        text = re.sub(
            r"\*\(const kd_vec3_f32 \*\)(kd_at\d\(" + name + r", [^)]*\))",
            r"kd_ldg3((const float *)\1)",
            text,
        )
    if "kd_ldg3(" in text:
        text = text.replace("struct kd_vec3_f32 { float c[3]; };",
                            "struct kd_vec3_f32 { float c[3]; };\n" + _LDG3)  # fmt: skip
    return text


def plain_div(text: str) -> str:
    """``kd_ifloordiv(a, b)`` as ``(a / b)``: exact for non-negative operands."""
    out, count = re.subn(r"kd_ifloordiv\((\w+), (\w+)\)", r"(\1 / \2)", text)
    if not count:
        raise RuntimeError("no floor division to replace")
    return out


def rows_grid(text: str) -> str:
    """The 2-d thread index from a grid of rows (blockIdx.y) instead of a division."""
    prologue = re.compile(
        r"const unsigned int kd_i = blockIdx\.x \* blockDim\.x \+ threadIdx\.x; "
        r"if \(kd_i >= kd_g\.n\) return; unsigned int kd_r = kd_i; "
        r"const int kd_t1 = \(int\)\(kd_r % kd_g\.dim\[1\]\); kd_r /= kd_g\.dim\[1\]; "
        r"const int kd_t0 = \(int\)kd_r;"
    )
    new = (
        "const unsigned int kd_c = blockIdx.x * blockDim.x + threadIdx.x; "
        "if (kd_c >= kd_g.dim[1]) return; const int kd_t1 = (int)kd_c; "
        "const int kd_t0 = (int)blockIdx.y;"
    )
    out, count = prologue.subn(new, text)
    if not count:
        raise RuntimeError("kdsl's n-d prologue changed; the rows variant needs updating")
    return out


#: NVRTC options of kdsl's IEEE builds (``--fmad=false`` among them), less the arch.
KDSL_OPTIONS = tuple(o for o in nvrtc.options("sm_90") if not o.startswith("--gpu-architecture"))
#: The variant compiled with NVRTC's defaults (FMA contraction on) like the hand-written.
FMAD = "kdsl fmad (not bit-exact)"
#: kdsl's own fast entry (``kdsl/backends/cuda/variants.py``) as generated; for Jacobi
#: launched as its 2-d grid of 256-thread rows (what ``geometry.nd_geometry`` picks).
FAST, FAST_ROWS = "kdsl fast entry", "kdsl fast entry (rows)"


def variants() -> dict[str, dict[str, tuple[str, str]]]:
    """``{workload: {variant: (source, entry)}}`` of every variant.

    Variants named ``hand-written...`` and ``FMAD`` build with NVRTC's defaults, the
    others with kdsl's options (``KDSL_OPTIONS``).
    """
    from suite.cupy_impl import KERNELS_SOURCE

    jac, jentry = kdsl_source(K.jacobi_kernel)
    clo, centry = kdsl_source(K.cloth_kernel)
    jac_k = as_device_function(jac, jentry, SHIM_JACOBI)
    clo_k = as_device_function(clo, centry, SHIM_CLOTH)
    return {
        "jacobi": {
            "hand-written 2d (cupy)": (KERNELS_SOURCE, "jacobi"),
            "hand-written 1d + div": (HAND_1D, "jacobi_1d"),
            "kdsl": (jac_k, "shim"),
            "kdsl narrow": (narrow(jac_k), "shim"),
            "kdsl narrow+ldg": (ldg(narrow(jac_k), ["v0"]), "shim"),
            "kdsl offsets32": (offsets32(jac_k), "shim"),
            "kdsl rows+offsets32+ldg": (ldg(offsets32(rows_grid(jac_k)), ["v0"]), "shim"),
            "kdsl rows": (rows_grid(jac_k), "shim"),
            "kdsl rows+narrow+ldg": (ldg(narrow(rows_grid(jac_k)), ["v0"]), "shim"),
            FAST_ROWS: (
                as_device_function(jac, fast_entry_name(K.jacobi_kernel.key), SHIM_JACOBI),
                "shim",
            ),
            FMAD: (jac_k, "shim"),
        },
        "cloth": {
            "hand-written (cupy)": (KERNELS_SOURCE, "cloth"),
            "kdsl": (clo_k, "shim"),
            "kdsl narrow": (narrow(clo_k), "shim"),
            "kdsl ldg": (ldg(clo_k, ["v0", "v1"]), "shim"),
            "kdsl div": (plain_div(clo_k), "shim"),
            "kdsl narrow+ldg+div": (plain_div(ldg(narrow(clo_k), ["v0", "v1"])), "shim"),
            "kdsl offsets32": (offsets32(clo_k), "shim"),
            "kdsl offsets32+ldg+div": (plain_div(ldg(offsets32(clo_k), ["v0", "v1"])), "shim"),
            FAST: (
                as_device_function(clo, fast_entry_name(K.cloth_kernel.key), SHIM_CLOTH),
                "shim",
            ),
            FMAD: (clo_k, "shim"),
        },
    }


_PTX_COUNTS = {
    "mul.lo.s64": r"\bmul\.lo\.s64\b",
    "mul.wide": r"\bmul\.wide\.s32\b|\bmad\.wide\.s32\b",
    "div/rem": r"\b(div|rem)\.(s|u)32\b",
    "ld.global": r"\bld\.global\.(f32|v\d\.f32)\b",
    "ld.global.nc": r"\bld\.global\.nc\.",
    "instructions": r"^\s+[a-z@]",
}


def _kdsl_built(name: str) -> bool:
    return not name.startswith("hand-written") and name != FMAD


def ptx_counts(source: str, entry: str, kdsl_options: bool) -> dict[str, int]:
    """Counts of some PTX instructions in ``entry`` compiled for ``sm_90``."""
    text = _ptx(source, kdsl_options)
    body = text[text.index(f".entry {entry}(") :]
    body = body[: body.index("\n}") + 2]
    return {k: len(re.findall(p, body, flags=re.M)) for k, p in _PTX_COUNTS.items()}


def sass_counts(source: str, entry: str, kdsl_options: bool, nvdisasm: str) -> dict[str, int]:
    """Counts of SASS instructions of ``entry`` for ``sm_90``: NVRTC's PTX through the
    ``ptxas`` on PATH (its PTX version taken down to ``ptxas``'s own when older), then
    ``nvdisasm``."""
    ptx = _ptx(source, kdsl_options)
    with tempfile.TemporaryDirectory() as tmp:
        ptx_path, cubin = Path(tmp, "v.ptx"), Path(tmp, "v.cubin")
        ptx_path.write_text(ptx)
        r = subprocess.run(["ptxas", "-arch=sm_90", str(ptx_path), "-o", str(cubin)],
                           capture_output=True, text=True)  # fmt: skip
        have = re.search(r"current version is '([\d.]+)'", r.stderr)
        if r.returncode and have:
            ptx_path.write_text(
                re.sub(r"^\.version [\d.]+", f".version {have.group(1)}", ptx, flags=re.M)
            )
            r = subprocess.run(["ptxas", "-arch=sm_90", str(ptx_path), "-o", str(cubin)],
                               capture_output=True, text=True)  # fmt: skip
        if r.returncode:
            raise RuntimeError(f"ptxas failed: {r.stderr.strip()}")
        text = subprocess.run([nvdisasm, "-c", str(cubin)],
                              capture_output=True, text=True, check=True).stdout  # fmt: skip
    text = text[text.index(f".text.{entry}:") :]
    end = text.find(".section", 1)
    text = text if end < 0 else text[:end]
    ins = re.findall(r"/\*[0-9a-f]{4}\*/\s+(?:@!?U?P\w+\s+)?([A-Z][A-Z0-9_.]*)", text)
    ops = [i.split(".")[0] for i in ins]
    return {
        "SASS": len(ins),
        "IMAD.WIDE": sum(i.startswith("IMAD.WIDE") for i in ins),
        "IMAD(.HI)": sum(o == "IMAD" and not i.startswith("IMAD.WIDE") for o, i in zip(ops, ins)),
        "LDG": ops.count("LDG"),
        "LDG.CONSTANT": sum(i.startswith("LDG") and "CONSTANT" in i for i in ins),
        "FFMA": ops.count("FFMA"),
        "MUFU": ops.count("MUFU"),
    }


def _ptx(source: str, kdsl_options: bool) -> str:
    from cupy_backends.cuda.libs import nvrtc as lib

    opts = list(KDSL_OPTIONS) if kdsl_options else ["--std=c++17"]
    prog = lib.createProgram(source, "variant.cu", [], [])
    try:
        lib.compileProgram(prog, [f"--gpu-architecture={nvrtc.DEFAULT_ARCH}", *opts])
        text = lib.getPTX(prog)
    finally:
        lib.destroyProgram(prog)
    return (text.decode() if isinstance(text, bytes) else text).rstrip("\0")


def compile_only(nvdisasm: str | None) -> dict[str, Any]:
    """PTX (and with ``nvdisasm``, SASS) counts of every variant (no GPU)."""
    out: dict[str, Any] = {}
    for workload, vs in variants().items():
        print(f"\n{workload}")
        header = False
        for name, (src, entry) in vs.items():
            counts = ptx_counts(src, entry, _kdsl_built(name))
            if nvdisasm:
                counts = {**counts, **sass_counts(src, entry, _kdsl_built(name), nvdisasm)}
            if not header:
                print(f"  {'variant':26s}" + "".join(f"{c:>13s}" for c in counts))
                header = True
            out[f"{workload}/{name}"] = counts
            print(f"  {name:26s}" + "".join(f"{v:13d}" for v in counts.values()))
    return out


# -- timing on a GPU ---------------------------------------------------------------------
def _graph_time(launch: Callable[[], None], per_graph: int, reps: int) -> float:
    """Milliseconds per launch of ``launch`` replayed from a CUDA graph (CuPy capture)."""
    import cupy

    stream = cupy.cuda.Stream(non_blocking=True)
    with stream:
        launch()
        stream.synchronize()
        stream.begin_capture()
        for _ in range(per_graph):
            launch()
        graph = stream.end_capture()
        graph.launch(stream)
        stream.synchronize()
        samples = []
        for _ in range(reps):
            start, end = cupy.cuda.Event(), cupy.cuda.Event()
            start.record(stream)
            graph.launch(stream)
            end.record(stream)
            end.synchronize()
            samples.append(cupy.cuda.get_elapsed_time(start, end) / per_graph)
    return float(np.median(samples))


def _check(name: str, got: dict[str, np.ndarray], workload: str, ins: dict) -> None:
    ref = getattr(W, f"{workload}_reference")(ins)
    for key, want in ref.items():
        g = np.asarray(got[key]).reshape(np.shape(want))
        err = float(np.max(np.abs(g - want)))
        if not err <= 1e-4 * max(1.0, float(np.max(np.abs(want)))):
            raise RuntimeError(f"{workload} / {name}: {key} off by {err}")


def _cupy_runners(workload: str, ins: dict) -> dict[str, Callable[[], dict]]:
    """``{variant: launch}``; each launch also returns nothing (outputs read after)."""
    import cupy

    f32 = np.float32
    out: dict[str, Any] = {}
    for name, (src, entry) in variants()[workload].items():
        opts = KDSL_OPTIONS if _kdsl_built(name) else ("--std=c++17",)
        kern = cupy.RawModule(code=src, options=opts).get_function(entry)
        if workload == "jacobi":
            u = cupy.asarray(ins["u"])
            res = cupy.zeros_like(u)
            rows, cols = u.shape
            if name.startswith("hand-written 2d"):
                call = (((cols + 31) // 32, (rows + 7) // 8), (32, 8),
                        (u, res, np.int32(rows), np.int32(cols)))  # fmt: skip
            elif name.startswith("hand-written 1d"):
                call = (((rows * cols + 255) // 256,), (256,),
                        (u, res, np.int32(rows), np.int32(cols)))  # fmt: skip
            else:
                grid = (
                    ((cols + 255) // 256, rows) if "rows" in name else ((rows * cols + 255) // 256,)
                )
                i64, u32 = np.int64, np.uint32
                call = (grid, (256,), (u, res, i64(rows), i64(cols), i64(4 * cols), i64(4),
                                       u32(rows * cols), u32(rows), u32(cols)))  # fmt: skip
            outs = {"out": res}
        else:
            x, v = cupy.asarray(ins["x"]), cupy.asarray(ins["v"])
            xo, vo = cupy.zeros_like(x), cupy.zeros_like(v)
            g, n = ins["grid"], len(ins["x"])
            common = (f32(ins["spacing"]), f32(ins["stiffness"]), f32(ins["inv_mass"]),
                      *(f32(c) for c in ins["gravity"]), f32(ins["dt"]))  # fmt: skip
            if name.startswith("hand-written"):
                call = (((n + 255) // 256,), (256,), (x, v, xo, vo, np.int32(g), *common))
            else:
                call = (((n + 255) // 256,), (256,), (x, v, xo, vo, np.int64(n), np.int64(12),
                                                     np.int32(g), *common, np.uint32(n)))  # fmt: skip
            outs = {"x_out": xo, "v_out": vo}

        def launch(kern=kern, call=call) -> None:
            kern(*call)

        launch()
        cupy.cuda.get_current_stream().synchronize()
        _check(name, {k: cupy.asnumpy(a) for k, a in outs.items()}, workload, ins)
        out[name] = launch
    return out


def _kdsl_launches(workload: str, ins: dict, per_graph: int, reps: int) -> dict[str, float]:
    """kdsl's own launches: plain, prepared and graph replay (ms per launch)."""
    kernel = K.jacobi_kernel if workload == "jacobi" else K.cloth_kernel
    if workload == "jacobi":
        u = wp.array(ins["u"], dtype=float, device="cuda:0")
        o = wp.zeros(ins["u"].shape, dtype=float, device="cuda:0")
        dim, args, outs = ins["u"].shape, [u, o], {"out": o}
    else:
        n = len(ins["x"])
        args = [wp.from_numpy(ins["x"], dtype=wp.vec3, device="cuda:0"),
                wp.from_numpy(ins["v"], dtype=wp.vec3, device="cuda:0"),
                wp.zeros(n, dtype=wp.vec3, device="cuda:0"), wp.zeros(n, dtype=wp.vec3, device="cuda:0"),
                ins["grid"], ins["spacing"], ins["stiffness"], ins["inv_mass"],
                wp.vec3(*ins["gravity"]), ins["dt"]]  # fmt: skip
        dim, outs = n, {"x_out": args[2], "v_out": args[3]}
    wp.launch(kernel, dim=dim, inputs=args, device="cuda:0")
    _check("kdsl launch", {k: a.numpy() for k, a in outs.items()}, workload, ins)
    stream = wp.get_stream("cuda:0")
    cmd = wp.launch(kernel, dim=dim, inputs=args, device="cuda:0", record_cmd=True)

    def timed(step: Callable[[], None], count: int) -> float:
        samples = []
        for _ in range(reps):
            stream.synchronize()
            t = time.perf_counter()
            step()
            stream.synchronize()
            samples.append((time.perf_counter() - t) * 1e3 / count)
        return float(np.median(samples))

    def plain() -> None:
        for _ in range(per_graph):
            wp.launch(kernel, dim=dim, inputs=args, device="cuda:0")

    def prepared() -> None:
        for _ in range(per_graph):
            cmd.launch()

    with wp.ScopedCapture(device="cuda:0") as cap:
        plain()
    graph = cap.graph
    wp.capture_launch(graph)
    return {
        "kdsl plain launches": timed(plain, per_graph),
        "kdsl prepared launches": timed(prepared, per_graph),
        "kdsl graph replay": timed(lambda: wp.capture_launch(graph), per_graph),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--compile-only", action="store_true", help="NVRTC + PTX counts, no GPU")
    p.add_argument("--nvdisasm", default=None, help="with --compile-only: SASS counts too")
    p.add_argument("--per-graph", type=int, default=200, help="launches per graph")
    p.add_argument("--reps", type=int, default=20, help="timed graph replays")
    p.add_argument("--json", type=Path, default=None)
    a = p.parse_args()
    if a.compile_only:
        data = compile_only(a.nvdisasm)
    else:
        rng = np.random.default_rng(0)
        data = {}
        for workload, size in (("jacobi", 4096), ("cloth", 256)):
            ins = getattr(W, f"{workload}_inputs")(size, rng)
            print(f"\n{workload} ({size}^2): ms per kernel")
            for name, launch in _cupy_runners(workload, ins).items():
                t = _graph_time(launch, a.per_graph, a.reps)
                data[f"{workload}/{name}"] = t
                print(f"  {name:28s} {t:10.5f}  (graph replay)")
            for name, t in _kdsl_launches(workload, ins, a.per_graph, a.reps).items():
                data[f"{workload}/{name}"] = t
                print(f"  {name:28s} {t:10.5f}")
    if a.json:
        a.json.write_text(json.dumps(data, indent=1))
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
