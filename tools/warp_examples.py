"""Run Warp's shipped examples with ``import kdsl as wp`` on the CPU (issue 14's example script).

    python tools/warp_examples.py                        # core, optim, tile, geometry
    python tools/warp_examples.py --groups core,optim    # the issue's done-when set only
    python tools/warp_examples.py --only example_wave --json out.json
    python tools/warp_examples.py --warp-from out.json   # reuse an earlier run's Warp results
    python tools/warp_examples.py --keep-warp render     # diagnostic: see below

Each example of ``warp/examples/<group>/`` (from the installed warp-lang, or
``--examples DIR``) runs twice, one after the other, each in its own subprocess with a
timeout (``--timeout``, 120 s) and its own scratch working directory:

1. as shipped, under real Warp on the CPU: does Warp itself run it without a GPU?
   When it does not, the reason is named from the error (a GPU, usd-core, Pillow,
   OpenGL, CuPy, a time-out...).
2. with its source rewritten for kdsl: every ``warp`` name token becomes ``kdsl``
   (``import warp as wp`` -> ``import kdsl as wp``, ``import warp.render`` ->
   ``import kdsl.render``, ``from warp.optim import SGD`` -> ``from kdsl.optim import SGD``,
   ``warp.examples.get_asset_directory()`` -> ``kdsl.examples...``); strings and comments
   are left alone. Nothing else is changed or provided: what kdsl lacks, submodules
   included, shows as a failure.

Both runs get the same arguments, the example's own flags as its argparse declares
them: ``--device cpu``, ``--stage-path None``, ``--headless``, 2 frames
(``--num-frames``) and 2 training iterations (``--train-iters``) where the example takes
them, and for some examples smaller sizes and step counts (``OVERRIDES``, after Warp's
own ``warp/tests/test_examples.py`` CPU options, made smaller). kdsl's CPU backend runs
with ``KDSL_CPU_THREADS=1`` (``--threads``). An example "runs" when it exits with status
0; otherwise its status is the first exception it stops on: the type and the first line
of the message (the full message, the example line it was raised from and the end of
stderr are in the JSON). An example that exits with status 0 after printing that it
needs CUDA ("This example only runs on CUDA devices.") is "skipped", not run.

``--keep-warp render --keep-warp examples`` is a diagnostic, not the recorded status:
it leaves ``warp.render``/``warp.examples`` (imports and attribute uses) on Warp, to
see where an example that stops at ``import kdsl.render`` would stop next.

The ``uses`` column is read from the source: tiles (``wp.tile_*``, ``launch_tiled``),
geometry (``Mesh``, ``HashGrid``, ``Volume``, ``Bvh``, ``warp.geometry``, their queries),
graphs (``ScopedCapture``/``capture_*``: "graphs" when the example captures on every
device, which Warp 1.19 supports on the CPU by recording and replaying the launches;
"graphs (cuda)" when every capture sits under an ``if`` that mentions CUDA, such as
``if self.use_cuda_graph:``), USD (``pxr``), OpenGL, and the other frameworks. Issue
14's done-when set is the core and optim examples that Warp runs on the CPU and that
need no tiles, no geometry and no graph capture on the CPU (tags "tiles", "geometry",
"graphs"); the table marks them with *.
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import tokenize
from collections import Counter
from pathlib import Path
from typing import Any

DEFAULT_GROUPS = ("core", "optim", "tile", "geometry")
DONE_WHEN_GROUPS = ("core", "optim")

#: Flag -> value (None: a switch), passed when the example's argparse declares the flag.
GENERIC_ARGS: dict[str, str | None] = {
    "--device": "cpu",
    "--stage-path": "None",
    "--headless": None,
    "--num-frames": "2",
    "--train-iters": "2",
}

#: Per example ("<group>/<name>"): smaller problems than the defaults, same flags for both runs.
OVERRIDES: dict[str, dict[str, str | None]] = {
    "core/example_fdtd_3d": {"--resolution": "48", "--num-steps": "10", "--steps-per-frame": "5"},
    "core/example_fft_poisson_navier_stokes_2d": {"--num-steps": "20", "--sim-substeps": "10"},
    "core/example_raycast": {"--width": "64", "--height": "64"},
    "core/example_raymarch": {"--width": "128", "--height": "64"},
    "core/example_torch": {"--num-particles": "100"},
    "optim/example_diffray": {"--height": "128"},
    "optim/example_fluid_checkpoint": {
        "--num-frames": "5", "--pressure-iterations": "3", "--segment-size": "3"},
    "optim/example_fluid_checkpoint_custom_backward": {
        "--num-frames": "5", "--pressure-iterations": "3", "--segment-size": "3"},
    "optim/example_navier_stokes_perturbation": {"--spin-up-steps": "3", "--lead-steps": "3"},
    "optim/example_particle_repulsion": {"--num-frames": "5"},
    "tile/example_tile_block_cholesky": {"-N": "2"},
    "tile/example_tile_mcgp": {"--height": "64", "--slices": "2"},
    "tile/example_tile_nbody": {"-N": "128"},
    "geometry/example_swept_volume": {"--num-samples": "4"},
}  # fmt: skip

#: Tag -> pattern searched in the example's source.
USES: dict[str, re.Pattern[str]] = {
    "tiles": re.compile(r"\bwp\.(tile\w*|launch_tiled)\b"),
    "geometry": re.compile(
        r"\bwp\.(Mesh|HashGrid|Volume|Bvh|MarchingCubes)\w*\b|\bwarp\.geometry\b"
        r"|\bwp\.(mesh|hash_grid|volume|bvh)_\w+"
    ),
    "graphs": re.compile(r"\bwp\.(ScopedCapture|capture_\w+)\b"),  # refined by graph_tag
    "usd": re.compile(r"\bpxr\b"),
    "opengl": re.compile(r"OpenGLRenderer|\bpyglet\b|render_opengl"),
    "torch": re.compile(r"^\s*import torch\b", re.M),
    "cupy": re.compile(r"^\s*import cupy\b", re.M),
    "jax": re.compile(r"^\s*import jax\b", re.M),
}

#: Runs one example in a subprocess: ``python runner.py PATH OUT_JSON ARGS...``.
RUNNER = r"""
import json, os, runpy, sys, traceback
path, out = sys.argv[1], sys.argv[2]
sys.argv = [path] + sys.argv[3:]
sys.path.insert(0, os.path.dirname(path))
res = {"status": "ok"}
try:
    runpy.run_path(path, run_name="__main__")
except SystemExit as e:
    if e.code not in (None, 0):
        res = {"status": "error", "type": "SystemExit", "message": str(e.code), "where": None}
except BaseException as e:
    frames = [f for f in traceback.extract_tb(e.__traceback__) if f.filename == path]
    where = f"line {frames[-1].lineno}: {frames[-1].line}" if frames else None
    res = {"status": "error", "type": type(e).__name__, "module": type(e).__module__,
           "message": str(e), "where": where}
    traceback.print_exc()
with open(out, "w") as f:
    json.dump(res, f)
sys.exit(0 if res["status"] == "ok" else 1)
"""


def default_examples_dir() -> Path:
    """``warp/examples`` of the installed warp-lang, found without importing it."""
    spec = importlib.util.find_spec("warp")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("warp_examples: warp-lang is not installed (pip install -e '.[bench]'), "
                         "or pass --examples DIR")  # fmt: skip
    return Path(next(iter(spec.submodule_search_locations))) / "examples"


def find_examples(root: Path, groups: list[str], only: list[str]) -> list[tuple[str, Path]]:
    found = []
    for g in groups:
        for p in sorted((root / g).glob("example_*.py")):
            if not only or p.stem in only or f"{g}/{p.stem}" in only:
                found.append((f"{g}/{p.stem}", p))
    return found


def declared_flags(source: str) -> set[str]:
    return set(re.findall(r"add_argument\(\s*[\"'](-[\w-]+)[\"']", source))


def example_args(key: str, source: str) -> list[str]:
    flags = declared_flags(source)
    chosen = {f: v for f, v in GENERIC_ARGS.items() if f in flags}
    chosen.update({f: v for f, v in OVERRIDES.get(key, {}).items() if f in flags})
    args: list[str] = []
    for f, v in chosen.items():
        args += [f] if v is None else [f, v]
    return args


def uses(source: str) -> list[str]:
    tags = [tag for tag, pat in USES.items() if pat.search(source)]
    return [graph_tag(source) if t == "graphs" else t for t in tags]


def graph_tag(source: str) -> str:
    """Tag "graphs (cuda)" when every capture is under an ``if`` mentioning CUDA, else "graphs"."""
    lines = source.splitlines()
    for n, line in enumerate(lines):
        if not re.search(r"\bwp\.(ScopedCapture|capture_begin)\b", line):
            continue
        indent, guarded = len(line) - len(line.lstrip()), False
        for above in reversed(lines[:n]):
            stripped = above.lstrip()
            if not stripped or stripped.startswith("#") or len(above) - len(stripped) >= indent:
                continue
            indent = len(above) - len(stripped)  # an enclosing block's header
            if re.match(r"(el)?if\b", stripped) and "cuda" in stripped.lower():
                guarded = True
                break
            if indent == 0:
                break
        if not guarded:
            return "graphs"
    return "graphs (cuda)"


def to_kdsl(source: str, keep: frozenset[str] = frozenset()) -> str:
    """Every ``warp`` name token becomes ``kdsl`` (same length: columns do not move).

    ``keep`` (a diagnostic, ``--keep-warp``): submodules whose ``warp.<name>`` stays Warp's.
    """
    lines = source.splitlines(keepends=True)
    toks = list(tokenize.generate_tokens(io.StringIO(source).readline))
    for i, tok in enumerate(toks):
        if tok.type != tokenize.NAME or tok.string != "warp":
            continue
        after = [t.string for t in toks[i + 1 : i + 3]]
        if len(after) == 2 and after[0] == "." and after[1] in keep:
            continue
        (row, col) = tok.start
        line = lines[row - 1]
        lines[row - 1] = line[:col] + "kdsl" + line[col + 4 :]
    return "".join(lines)


def run_one(path: Path, args: list[str], workdir: Path, timeout: float,
            env: dict[str, str]) -> dict[str, Any]:  # fmt: skip
    """Run ``path`` with ``args`` in ``workdir``; the runner's JSON plus seconds and stderr."""
    workdir.mkdir(parents=True, exist_ok=True)
    runner = workdir / "_runner.py"
    runner.write_text(RUNNER)
    out = workdir / "_result.json"
    start = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, str(runner), str(path), str(out), *args],
                              cwd=workdir, env=env, capture_output=True, text=True,
                              timeout=timeout)  # fmt: skip
    except subprocess.TimeoutExpired as e:
        err = e.stderr.decode(errors="replace") if isinstance(e.stderr, bytes) else e.stderr or ""
        return {"status": "timeout", "type": "Timeout", "message": f"no exit within {timeout:g} s",
                "where": None, "seconds": round(time.perf_counter() - start, 1),
                "stderr_tail": err[-2000:]}  # fmt: skip
    seconds = round(time.perf_counter() - start, 1)
    if out.exists():
        res = json.loads(out.read_text())
    else:  # killed by a signal, or the interpreter died
        res = {"status": "error", "type": "Crash", "message": f"exit status {proc.returncode}",
               "where": None}  # fmt: skip
    res["seconds"] = seconds
    res["stdout_tail"] = (proc.stdout or "")[-1000:]
    res["stderr_tail"] = (proc.stderr or "")[-2000:]
    skip = _EARLY_EXIT.search(res["stdout_tail"]) if res["status"] == "ok" else None
    if skip:  # exit status 0, but the example declined to run on this device
        res.update(status="skipped", type="skipped", message=skip.group(0).strip())
    return res


#: What an example prints when it exits early (status 0) because there is no CUDA device.
_EARLY_EXIT = re.compile(
    r"^.*\b(only runs on CUDA|requires a CUDA|requires CUDA)\b.*$", re.M | re.I
)


def first_line(res: dict[str, Any]) -> str:
    """``Type: first line of the message`` (or ``ok``)."""
    if res["status"] == "ok":
        return "ok"
    msg = (res.get("message") or "").strip().splitlines()
    return f"{res['type']}: {msg[0] if msg else ''}".rstrip(": ")


_NEEDS = (  # (pattern over "Type: message" and stderr, reason) for runs that fail under Warp
    (re.compile(r"No module named '?pxr"), "needs usd-core"),
    (re.compile(r"No module named '?PIL"), "needs Pillow"),
    (re.compile(r"No module named '?(pyglet|OpenGL|imgui)|OpenGL|pyglet"), "needs OpenGL"),
    (re.compile(r"No module named '?matplotlib"), "needs matplotlib"),
    (re.compile(r"cupy|CUDA driver|cudaErrorNoDevice|CUDARuntimeError", re.I), "needs a GPU"),
    (re.compile(r"cuda|gpu", re.I), "needs a GPU"),
)


def warp_verdict(res: dict[str, Any]) -> str:
    """Return "yes", or why Warp does not run the example on the CPU."""
    if res["status"] == "ok":
        return "yes"
    if res["status"] == "timeout":
        return "no: timed out"
    if res["status"] == "skipped":
        return "no: needs a GPU (exits early on the CPU)"
    if "Warp CUDA error" in res.get("stderr_tail", ""):
        return "no: needs a GPU"  # e.g. pinned host memory needs the CUDA driver
    text = first_line(res)
    for pat, reason in _NEEDS:
        if pat.search(text):
            return f"no: {reason}"
    return f"no: {text}"


def in_done_when_set(row: dict[str, Any]) -> bool:
    return (row["group"] in DONE_WHEN_GROUPS and row["warp_cpu"] == "yes"
            and not {"tiles", "geometry", "graphs"} & set(row["uses"]))  # fmt: skip


def run_all(examples: list[tuple[str, Path]], timeout: float, threads: int,
            warp_from: dict[str, Any] | None, log: Any,
            keep: frozenset[str] = frozenset()) -> list[dict[str, Any]]:  # fmt: skip
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg",
               KDSL_CPU_THREADS=str(threads))  # fmt: skip
    rows = []
    with tempfile.TemporaryDirectory(prefix="warp-examples-") as tmp:
        for key, path in examples:
            source = path.read_text()
            args = example_args(key, source)
            row: dict[str, Any] = {"example": key, "group": key.split("/")[0],
                                   "args": args, "uses": uses(source)}  # fmt: skip
            if warp_from is not None and key in warp_from:
                row["warp"] = warp_from[key]
            else:
                row["warp"] = run_one(path, args, Path(tmp, "warp", key), timeout, env)
            row["warp_cpu"] = warp_verdict(row["warp"])
            kpath = Path(tmp, "kdsl-src", key + ".py")
            kpath.parent.mkdir(parents=True, exist_ok=True)
            kpath.write_text(to_kdsl(source, keep))
            row["kdsl"] = run_one(kpath, args, Path(tmp, "kdsl", key), timeout, env)
            row["kdsl_status"] = first_line(row["kdsl"])
            row["done_when"] = in_done_when_set(row)
            rows.append(row)
            print(f"  {key}: warp {row['warp_cpu']} ({row['warp']['seconds']} s); kdsl "
                  f"{row['kdsl_status'][:100]} ({row['kdsl']['seconds']} s)", file=log,
                  flush=True)  # fmt: skip
    return rows


def _cell(text: str, width: int = 110) -> str:
    text = text.replace("|", "\\|").replace("`", "'")
    return text if len(text) <= width else text[: width - 3] + "..."


def render(rows: list[dict[str, Any]]) -> str:
    lines = []
    for title, part in (
        ("core and optim (issue 14's done-when set: the rows marked *)",
         [r for r in rows if r["group"] in DONE_WHEN_GROUPS]),
        ("tile and geometry", [r for r in rows if r["group"] not in DONE_WHEN_GROUPS]),
    ):  # fmt: skip
        if not part:
            continue
        lines += [f"### {title}", "",
                  "| example | uses | Warp on cpu | Warp s | kdsl | kdsl s |",
                  "| --- | --- | --- | --- | --- | --- |"]  # fmt: skip
        for r in part:
            name = r["example"] + (" *" if r["done_when"] else "")
            lines.append(
                f"| {name} | {', '.join(r['uses']) or '-'} | {_cell(r['warp_cpu'], 60)} | "
                f"{r['warp']['seconds']} | {_cell(r['kdsl_status'])} | {r['kdsl']['seconds']} |"
            )
        lines.append("")
    lines += summary(rows)
    return "\n".join(lines)


def summary(rows: list[dict[str, Any]]) -> list[str]:
    warp_ok = [r for r in rows if r["warp_cpu"] == "yes"]
    done = [r for r in rows if r["done_when"]]
    out = [
        f"Warp runs {len(warp_ok)} of {len(rows)} examples on the CPU; kdsl runs "
        f"{sum(r['kdsl_status'] == 'ok' for r in warp_ok)} of those "
        f"({sum(r['kdsl_status'] == 'ok' for r in rows)} of all {len(rows)}).",
        f"Done-when set (core and optim examples that Warp runs on the CPU, with no tiles, "
        f"geometry or graph capture on the CPU): kdsl runs "
        f"{sum(r['kdsl_status'] == 'ok' for r in done)} of {len(done)}.",
    ]
    graphs = [r for r in warp_ok if r["group"] in DONE_WHEN_GROUPS and "graphs" in r["uses"]
              and not {"tiles", "geometry"} & set(r["uses"])]  # fmt: skip
    if graphs:
        out.append(
            f"Outside it only for capturing graphs on the CPU: "
            f"{', '.join(r['example'] for r in graphs)}; kdsl runs "
            f"{sum(r['kdsl_status'] == 'ok' for r in graphs)} of {len(graphs)}."
        )
    out += [
        "",
        "First errors under kdsl of the examples Warp runs on the CPU, most frequent first:",
        "",
    ]
    ranked = first_errors(warp_ok)
    out += [f"- {n} x `{_cell(err, 200)}`: {', '.join(ex)}" for err, n, ex in ranked] or ["- none"]
    return out


def first_errors(rows: list[dict[str, Any]]) -> list[tuple[str, int, list[str]]]:
    """Distinct first errors of the failing rows: (error, count, examples), most frequent first."""
    counts = Counter(r["kdsl_status"] for r in rows if r["kdsl_status"] != "ok")
    return [(err, n, [r["example"] for r in rows if r["kdsl_status"] == err])
            for err, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=Path, help="Warp's examples directory (default: the "
                    "installed warp-lang's warp/examples)")  # fmt: skip
    ap.add_argument("--groups", default=",".join(DEFAULT_GROUPS),
                    help="comma-separated subdirectories (default: %(default)s)")  # fmt: skip
    ap.add_argument("--only", nargs="*", default=[], help="example names (example_wave or "
                    "core/example_wave)")  # fmt: skip
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per run (default 120)")
    ap.add_argument("--threads", type=int, default=1, help="KDSL_CPU_THREADS for kdsl's runs")
    ap.add_argument("--warp-from", type=Path, metavar="JSON",
                    help="take the Warp runs from an earlier --json output")  # fmt: skip
    ap.add_argument("--json", type=Path, metavar="PATH", help="write every result as JSON")
    ap.add_argument("--keep-warp", action="append", default=[], metavar="MODULE",
                    help="diagnostic only, not the recorded status: leave warp.MODULE imports "
                    "(render, examples...) on Warp to see where an example stops next")  # fmt: skip
    args = ap.parse_args(argv)
    root = args.examples or default_examples_dir()
    examples = find_examples(root, [g for g in args.groups.split(",") if g], args.only)
    if not examples:
        print(f"warp_examples: no examples under {root}", file=sys.stderr)
        return 2
    warp_from = None
    if args.warp_from:
        warp_from = {
            r["example"]: r["warp"] for r in json.loads(args.warp_from.read_text())["rows"]
        }
    print(f"Running {len(examples)} examples from {root}", file=sys.stderr)
    keep = frozenset(args.keep_warp)
    rows = run_all(examples, args.timeout, args.threads, warp_from, sys.stderr, keep)
    if keep:
        print(f"(diagnostic: warp.{{{','.join(sorted(keep))}}} left on Warp)\n")
    print(render(rows))
    if args.json:
        report = {"examples_dir": str(root), "timeout_s": args.timeout,
                  "keep_warp": sorted(keep), "rows": rows,
                  "first_errors": first_errors([r for r in rows if r["warp_cpu"] == "yes"])}  # fmt: skip
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
