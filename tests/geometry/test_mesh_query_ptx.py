"""Compile-only (no GPU needed): the mesh query kernels (closest point, furthest point,
signed by normal, ray, any hit, counted hits) through NVRTC for sm_90, each reading its
BVH nodes with 16-byte vector loads (``BvhNode`` is 16-byte aligned), as the BVH
queries do."""

from __future__ import annotations

import re

import pytest

import kdsl as wp


@wp.kernel
def _closest(mesh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, p[i], 10.0)
    out[i] = q.u + float(q.face)


@wp.kernel
def _furthest(mesh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_furthest_point_no_sign(mesh, p[i], 0.0)
    out[i] = q.u + float(q.face)


@wp.kernel
def _signed(mesh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point_sign_normal(mesh, p[i], 10.0)
    out[i] = q.sign


@wp.kernel
def _rays(mesh: wp.uint64, s: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3),
          out: wp.array(dtype=float)):  # fmt: skip
    i = wp.tid()
    q = wp.mesh_query_ray(mesh, s[i], d[i], 1.0e6)
    hits = wp.mesh_query_ray_count_intersections(mesh, s[i], d[i])
    out[i] = q.t + float(hits) + float(wp.mesh_query_ray_anyhit(mesh, s[i], d[i], 1.0e6))


@pytest.mark.parametrize("kernel", [_closest, _furthest, _signed, _rays])
def test_mesh_queries_compile_with_vector_node_loads(kernel):
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    ptx = nvrtc.compile_source(generate(m, [kernel.key]).text, "sm_90").ptx
    loads = re.findall(r"\bld\.[\w.]+", ptx)
    assert any(".v4" in ld for ld in loads), sorted(set(loads))
