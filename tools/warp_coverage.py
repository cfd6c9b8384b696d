"""Which of Warp's public names and kernel builtins kdsl lacks (issue 14's coverage script).

    python tools/warp_coverage.py                 # counts and grouped lists
    python tools/warp_coverage.py --json out.json # the same, as JSON
    python tools/warp_coverage.py --quiet         # counts only

Needs warp-lang (the ``bench`` extra); written against Warp 1.19.

**Public names.** Warp 1.19 has no ``__all__``: its public names are ``dir(warp)``,
taken right after ``import warp`` (before anything imports ``warp.optim``,
``warp.render``, ...), without the names that start with ``_``. The four submodules
that ``import warp`` binds (``config``, ``types``, ``utils``, ``build_experimental``)
are kept, since programs reach them as ``wp.config.mode`` and the like; they are
marked "(module)". kdsl has a name when ``hasattr(kdsl, name)``. Missing names fall
into the first matching group:

- geometry: ``Mesh*``, ``Bvh*``, ``HashGrid*``, ``Volume*``, ``MarchingCubes*`` and the
  ``mesh_``, ``bvh_``, ``hash_grid_``, ``volume_``, ``marching_cubes`` functions,
  ``is_cubql_available`` (cuBQL builds BVHs);
- tiles: ``tile``, ``tile_*``, ``launch_tiled`` and any other name containing ``tile``;
- CUDA graphs: ``Graph``, ``CaptureMode``, ``ScopedCapture``, ``capture_*``,
  ``is_conditional_graph_supported``, and JAX's graph modes and graph cache;
- multi-GPU and IPC: names with ``ipc``, ``peer_access`` or ``mempool_access``,
  ``ScopedPeerAccess``, ``ScopedMempoolAccess``, ``map_cuda_device``,
  ``unmap_cuda_device`` (foreign CUDA contexts);
- textures/OpenGL/fabric: ``Texture*``, ``texture_*``, ``GL*``, ``RegisteredGLBuffer``,
  ``*fabricarray*``;
- the rest.

**Kernel builtins.** Warp's builtin registry is ``warp._src.context.builtin_functions``
(name -> ``Function``; 355 names in 1.19). Left out: the tile builtins (``tile_*`` and
Warp's "Tile Primitives" group: ``assign``, ``untile``), counted but not listed, and the
helpers Warp's code generator emits for syntax that a program never calls by name
(``INTERNAL_BUILTINS``: subscripts, element and component writes, augmented
assignment, loop iteration, tuples and slices). The others are grouped as geometry
(the ``mesh_``, ``bvh_``, ``hash_grid_`` and ``volume_`` queries; the pure functions of
Warp's "Geometry" group, ``closest_point_edge_edge`` and ``intersect_tri_tri``, stay in
the rest), textures (``texture_sample``) and the rest.

kdsl has a kernel builtin when the frontend resolves the name to something it can
call: a builtin of kdsl's table (``kdsl.tools.builtins_doc.all_builtins()``, the table
docs/builtins.md is generated from), a public standard-library function
(``builtins_doc.stdlib_functions()``), a kdsl type the frontend constructs in kernels
(``kdsl.<name>`` with a scalar, vector, matrix, quaternion or transform
``__kdsl_type__``), one of Python's casts the frontend knows (``int``, ``float``,
``bool``), ``static``, or a loop construct (``range``, ``reversed``) that a tiny kernel
using it compiles with.

Lists are sorted; each name is in exactly one group. tests/tools/test_warp_coverage.py
runs this script.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import types
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script from a checkout
    sys.path.insert(0, str(ROOT))

PUBLIC_GROUPS = ("tiles", "geometry", "cuda_graphs", "multi_gpu_ipc", "textures_opengl_fabric",
                 "rest")  # fmt: skip
BUILTIN_GROUPS = ("geometry", "textures", "rest")

GROUP_TITLES = {
    "tiles": "tiles",
    "geometry": "geometry (Mesh, Bvh, HashGrid, Volume, MarchingCubes and their queries)",
    "cuda_graphs": "CUDA graphs",
    "multi_gpu_ipc": "multi-GPU and IPC",
    "textures_opengl_fabric": "textures, OpenGL and fabric arrays",
    "textures": "textures",
    "rest": "the rest",
}

#: Builtins Warp's code generator emits for syntax; a program never writes them by name.
INTERNAL_BUILTINS = frozenset({
    "address", "array_store", "assign_copy", "copy", "extract", "index", "indexref",
    "iter_next", "load", "slice", "store", "tuple",
})  # fmt: skip
#: ...and the augmented-assignment and component-write forms: ``*_inplace``, ``*_copy``.
INTERNAL_SUFFIXES = ("_inplace", "_copy")

_GEOMETRY_PUBLIC = re.compile(
    r"^(Mesh|Bvh|HashGrid|Volume|MarchingCubes)|^(mesh_|bvh_|hash_grid_|volume_|marching_cubes)"
    r"|^is_cubql_available$"
)
_GEOMETRY_BUILTIN = re.compile(r"^(mesh_|bvh_|hash_grid_|volume_)")
_GRAPHS = re.compile(
    r"^(Graph|CaptureMode|ScopedCapture|is_conditional_graph_supported|JaxCallableGraphMode"
    r"|clear_jax_callable_graph_cache)$|^capture_"
)
_MULTI_GPU = re.compile(
    r"ipc|peer_access|mempool_access|^Scoped(PeerAccess|MempoolAccess)$|^(un)?map_cuda_device$"
)
_TEXTURES = re.compile(r"^Texture|^texture_|^GL|^RegisteredGLBuffer$|fabricarray")


def load_warp() -> types.ModuleType:
    """``import warp`` (quietly); raises ImportError without warp-lang."""
    import warp

    warp.config.quiet = True
    return warp


def warp_public_names(warp: types.ModuleType) -> dict[str, str]:
    """Warp's public names, each with what it is ("module", "function", a class name...)."""
    out = {}
    for name in dir(warp):
        if name.startswith("_"):
            continue
        obj = getattr(warp, name)
        out[name] = "module" if isinstance(obj, types.ModuleType) else type(obj).__name__
    return out


def warp_builtins() -> dict[str, str]:
    """Every kernel builtin in Warp's registry, with its documentation group."""
    from warp._src.context import builtin_functions

    return {name: fn.group or "" for name, fn in builtin_functions.items()}


def is_tile_builtin(name: str, group: str) -> bool:
    return name.startswith("tile") or group == "Tile Primitives"


def is_internal_builtin(name: str) -> bool:
    return name in INTERNAL_BUILTINS or name.endswith(INTERNAL_SUFFIXES)


def public_group(name: str) -> str:
    if _GEOMETRY_PUBLIC.search(name):
        return "geometry"
    if "tile" in name.lower():
        return "tiles"
    if _GRAPHS.search(name):
        return "cuda_graphs"
    if _MULTI_GPU.search(name):
        return "multi_gpu_ipc"
    if _TEXTURES.search(name):
        return "textures_opengl_fabric"
    return "rest"


def builtin_group(name: str) -> str:
    if _GEOMETRY_BUILTIN.search(name):
        return "geometry"
    if name.startswith("texture_"):
        return "textures"
    return "rest"


# --- what kdsl has ---------------------------------------------------------------------


def _compiles(make: Any) -> bool:
    """Whether the kernel ``make()`` returns compiles (to IR) with kdsl's frontend."""
    try:
        make().build_module()
    except Exception:  # any failure means the construct is not supported
        return False
    return True


def _loop_probes() -> dict[str, Any]:
    import kdsl

    def range_probe():
        @kdsl.kernel
        def k(n: int):
            x = 0.0
            for _i in range(n):
                x = x + 1.0

        return k

    def reversed_probe():
        @kdsl.kernel
        def k(n: int):
            x = 0.0
            for _i in reversed(range(n)):
                x = x + 1.0

        return k

    return {"range": range_probe, "reversed": reversed_probe}


def kdsl_kernel_names() -> dict[str, str]:
    """Names callable in kdsl kernels, each with where the frontend finds it."""
    import kdsl
    from kdsl.frontend.builtins import PYTHON_CASTS
    from kdsl.frontend.static import static
    from kdsl.ir.types import MatrixType, ScalarType, VectorType
    from kdsl.tools.builtins_doc import all_builtins, stdlib_functions

    out: dict[str, str] = {}
    for name in all_builtins():
        out[name] = "builtin"
    for name in stdlib_functions():
        out.setdefault(name, "stdlib")
    for name in dir(kdsl):
        t = getattr(getattr(kdsl, name), "__kdsl_type__", None)
        if not name.startswith("_") and isinstance(t, ScalarType | VectorType | MatrixType):
            out.setdefault(name, "type")
    for py in PYTHON_CASTS:
        out.setdefault(py.__name__, "python cast")
    if getattr(kdsl, "static", None) is static:
        out.setdefault("static", "static")
    for name, make in _loop_probes().items():
        if name not in out and _compiles(make):
            out[name] = "loop construct"
    return out


# --- the report --------------------------------------------------------------------------


def coverage() -> dict[str, Any]:
    """The whole report as a JSON-able dict."""
    warp = load_warp()
    import kdsl

    public = warp_public_names(warp)
    missing_public: dict[str, list[str]] = {g: [] for g in PUBLIC_GROUPS}
    for name in sorted(public):
        if not hasattr(kdsl, name):
            missing_public[public_group(name)].append(name)

    registry = warp_builtins()
    tile = sorted(n for n, g in registry.items() if is_tile_builtin(n, g))
    internal = sorted(n for n in registry if n not in tile and is_internal_builtin(n))
    considered = sorted(set(registry) - set(tile) - set(internal))
    have = kdsl_kernel_names()
    missing_builtins: dict[str, list[str]] = {g: [] for g in BUILTIN_GROUPS}
    for name in considered:
        if name not in have:
            missing_builtins[builtin_group(name)].append(name)
    n_missing_b = sum(len(v) for v in missing_builtins.values())
    n_missing_p = sum(len(v) for v in missing_public.values())
    return {
        "warp_version": warp.__version__,
        "public_names": {
            "total": len(public),
            "kdsl_has": len(public) - n_missing_p,
            "missing": n_missing_p,
            "missing_by_group": missing_public,
            "modules": sorted(n for n, k in public.items() if k == "module"),
        },
        "kernel_builtins": {
            "registry_total": len(registry),
            "tile": len(tile),
            "internal": internal,
            "non_tile": len(considered),
            "kdsl_has": len(considered) - n_missing_b,
            "missing": n_missing_b,
            "missing_by_group": missing_builtins,
            "kdsl_has_by_source": {n: have[n] for n in considered if n in have},
        },
    }


def render(report: dict[str, Any], quiet: bool = False) -> str:
    p, b = report["public_names"], report["kernel_builtins"]
    modules = set(p["modules"])
    lines = [
        f"Warp {report['warp_version']} public names: {p['total']}; kdsl has {p['kdsl_has']}, "
        f"lacks {p['missing']}",
    ]
    for g in PUBLIC_GROUPS:
        lines.append(f"  {GROUP_TITLES[g]}: {len(p['missing_by_group'][g])}")
    lines.append(
        f"Warp kernel builtins: {b['registry_total']} in the registry, {b['tile']} tile, "
        f"{len(b['internal'])} code-generator helpers; of the other {b['non_tile']} kdsl has "
        f"{b['kdsl_has']}, lacks {b['missing']}"
    )
    for g in BUILTIN_GROUPS:
        lines.append(f"  {GROUP_TITLES[g]}: {len(b['missing_by_group'][g])}")
    if quiet:
        return "\n".join(lines)
    lines += ["", "Public names kdsl lacks:"]
    for g in PUBLIC_GROUPS:
        names = [n + (" (module)" if n in modules else "") for n in p["missing_by_group"][g]]
        lines.append(f"- {GROUP_TITLES[g]} ({len(names)}): {', '.join(names) or '-'}")
    lines += ["", "Non-tile kernel builtins kdsl lacks:"]
    for g in BUILTIN_GROUPS:
        names = b["missing_by_group"][g]
        lines.append(f"- {GROUP_TITLES[g]} ({len(names)}): {', '.join(names) or '-'}")
    lines.append(f"(left out as code-generator helpers: {', '.join(b['internal'])})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", metavar="PATH", help="write the report as JSON")
    ap.add_argument("--quiet", action="store_true", help="print the counts only")
    args = ap.parse_args(argv)
    try:
        report = coverage()
    except ImportError as e:
        print(f"warp_coverage: needs warp-lang (pip install -e '.[bench]'): {e}", file=sys.stderr)
        return 2
    print(render(report, args.quiet))
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
