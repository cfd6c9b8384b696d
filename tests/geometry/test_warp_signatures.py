"""Issue 15's API as Warp 1.19 spells it: every mesh, BVH and geometry builtin has Warp's
overloads (parameter names, order and defaults), ``Mesh``, ``Bvh`` and the
``kdsl.utils`` primitives take Warp's parameters in Warp's order, and the defaults mean
what Warp's mean. The comparisons read warp-lang's own tables and skip where it is not
installed; the behaviour checks always run."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

import kdsl as wp
from kdsl.tools.builtins_doc import stdlib_functions

#: Issue 15's kernel builtins.
GEOMETRY_BUILTINS = (
    "mesh_query_point", "mesh_query_point_no_sign", "mesh_query_point_sign_normal",
    "mesh_query_point_sign_winding_number", "mesh_query_point_sign_parity",
    "mesh_query_furthest_point_no_sign", "mesh_query_ray", "mesh_query_ray_anyhit",
    "mesh_query_ray_count_intersections", "mesh_query_aabb", "mesh_query_aabb_next",
    "mesh_query_sphere", "mesh_query_next", "mesh_eval_position", "mesh_eval_velocity",
    "mesh_eval_face_normal", "mesh_get", "mesh_get_point", "mesh_get_velocity",
    "mesh_get_index", "mesh_get_bvh", "mesh_get_group_root", "bvh_query_aabb",
    "bvh_query_ray", "bvh_query_sphere", "bvh_query_capsule", "bvh_query_next",
    "bvh_get_group_root", "closest_point_edge_edge", "intersect_tri_tri", "lower_bound",
)  # fmt: skip
UTILS = ("array_scan", "radix_sort_pairs", "segmented_sort_pairs", "runlength_encode",
         "array_sum", "array_inner")  # fmt: skip


def _default(value) -> object:
    if value is None or value is inspect.Parameter.empty:
        return None
    value = float(value)
    return value if math.isfinite(value) else str(value)


def _kdsl_overloads(name: str) -> set[tuple]:
    fn = stdlib_functions()[name][2]
    return {
        tuple((p, _default(q.default)) for p, q in inspect.signature(o.fn).parameters.items())
        for o in fn.overloads
    }


def _params(fn) -> list[tuple[str, object]]:
    sig = inspect.signature(fn)
    return [(p, q.default) for p, q in sig.parameters.items() if p != "self"]


@pytest.fixture(scope="module")
def warp():
    warp = pytest.importorskip("warp")
    warp.config.quiet = True
    return warp


@pytest.mark.parametrize("name", GEOMETRY_BUILTINS)
def test_builtin_overloads_are_warps(warp, name):
    from warp._src.context import builtin_functions

    theirs = {
        tuple((k, _default((o.defaults or {}).get(k))) for k in o.input_types)
        for o in builtin_functions[name].overloads
    }
    ours = _kdsl_overloads(name)
    assert theirs <= ours, f"Warp's overloads kdsl lacks: {theirs - ours}"
    assert hasattr(wp, name)


@pytest.mark.parametrize("name", ["MeshQueryPoint", "MeshQueryRay"])
def test_query_structs_have_warps_fields(warp, name):
    fields = [f[0] for f in getattr(wp, name).__kdsl_type__.fields]
    assert fields == list(getattr(warp, name).vars)


@pytest.mark.parametrize("name", ["MeshQueryAABB", "BvhQuery"])
def test_opaque_query_structs_exist(warp, name):
    assert hasattr(warp, name) and hasattr(wp, name)


@pytest.mark.parametrize("cls", ["Mesh", "Bvh"])
def test_constructors_take_warps_parameters_in_warps_order(warp, cls):
    assert _params(getattr(wp, cls).__init__) == _params(getattr(warp, cls).__init__)


@pytest.mark.parametrize("name", UTILS)
def test_utils_take_warps_parameters(warp, name):
    assert _params(getattr(wp.utils, name)) == _params(getattr(warp.utils, name))


def test_mesh_parameters_by_position_mean_warps():
    pts = wp.array(np.eye(3, dtype=np.float32), dtype=wp.vec3)
    idx = wp.array(np.array([0, 1, 2, 0, 2, 1], np.int32))
    groups = wp.array(np.array([0, 1], np.int32))
    mesh = wp.Mesh(pts, idx, None, True, "median", 1, groups)  # Warp's order
    assert mesh.support_winding_number and mesh.bvh.constructor == "median"
    assert mesh.bvh.leaf_size == 1 and mesh.bvh.groups is groups
    assert wp.Mesh(pts, idx, bvh_leaf_size=None).bvh.leaf_size == 4  # None: Warp's default


@wp.kernel
def _far_ray(bvh: wp.uint64, out: wp.array(dtype=int)):
    # entering the boxes at t ~ 3e38: finite, beyond any bound but an infinite one
    q = wp.bvh_query_ray(bvh, wp.vec3(-3.0e28), wp.vec3(1.0e-10))
    i = -1
    n = 0
    while wp.bvh_query_next(q, i):
        n += 1
    out[0] = n


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_bvh_query_next_is_unbounded_by_default(backend):
    boxes = np.zeros((2, 3), np.float32)
    bvh = wp.Bvh(wp.array(boxes, dtype=wp.vec3), wp.array(boxes + 1, dtype=wp.vec3))
    out = wp.zeros(1, dtype=int)
    wp.launch(_far_ray, 1, [bvh.id, out], backend=backend)
    assert out.numpy()[0] == 2  # Warp's default max_dist is inf


def test_bvh_query_default_compiles_for_cuda():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = _far_ray.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    assert nvrtc.compile_source(generate(m, [_far_ray.key]).text, "sm_90").ptx


def test_every_builtin_and_query_struct_is_in_the_builtins_page():
    from kdsl.tools.builtins_doc import DOCS

    page = DOCS.read_text()
    for name in (*GEOMETRY_BUILTINS, "MeshQueryPoint", "MeshQueryRay", "MeshQueryAABB",
                 "BvhQuery"):  # fmt: skip
        assert f"\n| `{name}` |" in page, name
    assert "mesh_query_point_sign_normal(id: uint64, point: vec3f, max_dist: float, epsilon: float = 0.001)" in page
