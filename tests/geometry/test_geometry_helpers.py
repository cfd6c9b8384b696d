"""Warp's free geometry helpers on interp, cpu and cuda: ``closest_point_edge_edge``
(float32 and float64) and ``intersect_tri_tri`` against float64 brute force,
``closest_point_edge_edge``'s gradient through ``kdsl.Tape``, and ``lower_bound``
(every scalar dtype, both overloads) against NumPy with Warp's quirk (``end - 1`` when
every element is smaller)."""

# (No ``from __future__ import annotations``: the kernels made in functions name their
# dtypes through closures, which string annotations cannot reach.)
import numpy as np
import pytest

import kdsl as wp
from kdsl.stdlib.algorithms import SEARCH_DTYPES
from tests.geometry.mesh_targets import BACKENDS, central_differences, device_of


def _edge_kernel(V: type, S: type):
    @wp.kernel
    def edges(seg: wp.array2d(dtype=V), eps: S, out: wp.array(dtype=V)):
        i = wp.tid()
        out[i] = wp.closest_point_edge_edge(seg[i, 0], seg[i, 1], seg[i, 2], seg[i, 3], eps)

    return edges


EDGES = {np.float32: _edge_kernel(wp.vec3, wp.float32), np.float64: _edge_kernel(wp.vec3d, wp.float64)}


def segment_distance(p1, q1, p2, q2) -> float:
    """The distance between two segments, float64: the least over the interior critical
    point (when inside the unit square) and each side of the square."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    cands = []
    a, e, b = d1 @ d1, d2 @ d2, d1 @ d2
    denom = a * e - b * b
    if denom > 1e-12 * a * e:
        s = (b * (d2 @ r) - (d1 @ r) * e) / denom
        t = (a * (d2 @ r) - b * (d1 @ r)) / denom
        if 0 <= s <= 1 and 0 <= t <= 1:
            cands.append((s, t))
    for s in (0.0, 1.0):  # a fixed end of segment 1: project it on segment 2
        x = p1 + s * d1
        cands.append((s, np.clip((x - p2) @ d2 / e, 0, 1) if e > 0 else 0.0))
    for t in (0.0, 1.0):
        x = p2 + t * d2
        cands.append((np.clip((x - p1) @ d1 / a, 0, 1) if a > 0 else 0.0, t))
    return min(np.linalg.norm(p1 + s * d1 - p2 - t * d2) for s, t in cands)


def _segments(rng: np.random.Generator) -> np.ndarray:
    """Random segment pairs, then adversarial ones: parallel, collinear, crossing,
    sharing an end point, and degenerate (a point, two points)."""
    seg = rng.normal(size=(40, 4, 3))
    p = np.array([0.0, 0.0, 0.0])
    x, y = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    extra = [
        [p, x, p + y, x + y],  # parallel
        [p, x, 2 * x, 3 * x],  # collinear, apart
        [p, 2 * x, x - y, x + y],  # crossing at (1, 0, 0)
        [p, x, x, x + y],  # a shared end point
        [x, x, p + y, x + y],  # segment 1 a point
        [x, x, y, y],  # both points
        [p, x, 0.5 * x + 0.3 * y, 0.5 * x + 0.3 * y + np.array([0, 0, 1.0])],  # skew
    ]
    return np.concatenate([seg, np.array(extra)])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_closest_point_edge_edge_matches_brute_force(backend, dtype):
    seg = _segments(np.random.default_rng(11)).astype(dtype)
    dev = device_of(backend)
    V = wp.vec3 if dtype == np.float32 else wp.vec3d
    out = wp.zeros(len(seg), dtype=V, device=dev)
    wp.launch(EDGES[dtype], dim=len(seg), backend=backend, device=dev,
              inputs=[wp.array(seg, dtype=V, device=dev), dtype(1e-12), out])  # fmt: skip
    s, t, d = out.numpy().astype(np.float64).T
    seg = seg.astype(np.float64)
    tol = 2e-5 if dtype == np.float32 else 1e-10
    assert np.all((s >= 0) & (s <= 1) & (t >= 0) & (t <= 1))
    for i, (p1, q1, p2, q2) in enumerate(seg):
        ref = segment_distance(p1, q1, p2, q2)
        np.testing.assert_allclose(d[i], ref, atol=tol * (1 + ref), err_msg=f"pair {i}")
        # s and t name points the distance is measured between
        gap = np.linalg.norm(p1 + s[i] * (q1 - p1) - p2 - t[i] * (q2 - p2))
        np.testing.assert_allclose(gap, ref, atol=tol * (1 + ref), err_msg=f"pair {i}")


@wp.kernel
def edge_distance(p1: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    r = wp.closest_point_edge_edge(p1[i], wp.vec3(1.0, 0.2, 0.1), wp.vec3(0.3, -1.0, 0.5),
                                   wp.vec3(0.2, 1.0, 0.6), 1.0e-8)  # fmt: skip
    out[i] = r[2] + 0.5 * r[0] - 0.25 * r[1]


@pytest.mark.parametrize("backend", BACKENDS)
def test_closest_point_edge_edge_gradient(backend):
    dev = device_of(backend)
    p0 = np.array([[-1.0, 0.1, -0.3], [-0.5, 0.7, 0.2]], np.float32)
    n = len(p0)

    def loss(p: np.ndarray) -> np.ndarray:
        out = wp.zeros(n, dtype=float, device=dev)
        wp.launch(edge_distance, dim=n, backend=backend, device=dev,
                  inputs=[wp.array(p, dtype=wp.vec3, device=dev), out])  # fmt: skip
        return out.numpy().astype(np.float64)

    p = wp.array(p0, dtype=wp.vec3, device=dev, requires_grad=True)
    out = wp.zeros(n, dtype=float, device=dev, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(edge_distance, dim=n, inputs=[p, out], backend=backend, device=dev)
    tape.backward(grads={out: wp.ones(n, dtype=float, device=dev)})
    fd = central_differences(loss, p0)
    np.testing.assert_allclose(p.grad.numpy(), fd, rtol=1e-2, atol=1e-2)
    assert np.abs(fd).max() > 0.1


def _segment_hits_triangle(a, b, tri) -> tuple[bool, float]:
    """Whether segment ``ab`` meets triangle ``tri`` (float64), and how far the answer is
    from flipping (the least barycentric or segment margin; 0 when coplanar)."""
    v0, v1, v2 = tri
    e1, e2, d = v1 - v0, v2 - v0, b - a
    n = np.cross(e1, e2)
    denom = n @ d
    if abs(denom) < 1e-12:
        return False, 0.0
    t = n @ (v0 - a) / denom
    x = a + t * d
    area = n @ n
    w1 = n @ np.cross(x - v0, e2) / area
    w2 = n @ np.cross(e1, x - v0) / area
    bary = (1 - w1 - w2, w1, w2)
    margin = min(abs(t), abs(1 - t), *(abs(w) for w in bary))
    return (0 <= t <= 1 and min(bary) >= 0), margin


def tri_tri_reference(v, u) -> tuple[bool, float]:
    """Whether two non-coplanar triangles intersect: some edge of one meets the other."""
    hit, margin = False, np.inf
    for tri, other in ((v, u), (u, v)):
        for k in range(3):
            h, m = _segment_hits_triangle(other[k], other[(k + 1) % 3], tri)
            hit, margin = hit or h, min(margin, m)
    return hit, margin


@wp.kernel
def tri_tri(tris: wp.array2d(dtype=wp.vec3d), out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = wp.intersect_tri_tri(tris[i, 0], tris[i, 1], tris[i, 2], tris[i, 3], tris[i, 4],
                                  tris[i, 5])  # fmt: skip


@wp.kernel
def tri_tri32(tris: wp.array2d(dtype=wp.vec3), out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = wp.intersect_tri_tri(tris[i, 0], tris[i, 1], tris[i, 2], tris[i, 3], tris[i, 4],
                                  tris[i, 5])  # fmt: skip


@pytest.mark.parametrize("backend", BACKENDS)
def test_intersect_tri_tri_matches_brute_force(backend):
    rng = np.random.default_rng(12)
    tris = rng.normal(size=(300, 6, 3)) + rng.normal(size=(300, 1, 3)) * 0.3
    ref = [tri_tri_reference(t[:3], t[3:]) for t in tris]
    keep = np.array([m > 1e-6 for _, m in ref])  # answers that rounding cannot flip
    want = np.array([h for h, _ in ref])[keep].astype(int)
    assert 30 < want.sum() < len(want) - 30  # both answers are well represented
    dev = device_of(backend)
    for kernel, V, dtype in ((tri_tri, wp.vec3d, np.float64), (tri_tri32, wp.vec3, np.float32)):
        out = wp.zeros(len(tris), dtype=int, device=dev)
        wp.launch(kernel, dim=len(tris), backend=backend, device=dev,
                  inputs=[wp.array(tris.astype(dtype), dtype=V, device=dev), out])  # fmt: skip
        np.testing.assert_array_equal(out.numpy()[keep], want, err_msg=str(dtype))


@pytest.mark.parametrize("backend", BACKENDS)
def test_intersect_tri_tri_coplanar_and_touching(backend):
    z = 0.0
    a = [[0, 0, z], [2, 0, z], [0, 2, z]]
    cases = [
        (a + [[0.5, 0.5, z], [3, 0.5, z], [0.5, 3, z]], 1),  # coplanar, overlapping
        (a + [[3, 3, z], [5, 3, z], [3, 5, z]], 0),  # coplanar, apart
        (a + [[0.2, 0.2, z], [0.4, 0.2, z], [0.2, 0.4, z]], 1),  # coplanar, one inside
        (a + [[0.5, 0.5, -1], [0.5, 0.5, 1], [3, 3, 0.5]], 1),  # piercing
        (a + [[0.5, 0.5, 0.5], [1, 0.5, 1], [0.5, 1, 1]], 0),  # above, parallel-ish
        (a + [[2, 0, z], [3, 0, 1], [3, 1, -1]], 1),  # touching at a shared vertex
    ]
    tris = np.array([c for c, _ in cases], np.float64)
    dev = device_of(backend)
    out = wp.zeros(len(tris), dtype=int, device=dev)
    wp.launch(tri_tri, dim=len(tris), backend=backend, device=dev,
              inputs=[wp.array(tris, dtype=wp.vec3d, device=dev), out])  # fmt: skip
    assert out.numpy().tolist() == [want for _, want in cases]


def _search_kernel(S: type):
    @wp.kernel
    def search(arr: wp.array(dtype=S), q: wp.array(dtype=S), lo: int, hi: int,
               out: wp.array2d(dtype=int)):  # fmt: skip
        i = wp.tid()
        out[i, 0] = wp.lower_bound(arr, q[i])
        out[i, 1] = wp.lower_bound(arr, lo, hi, q[i])

    return search


SEARCH = {S: _search_kernel(S) for S in SEARCH_DTYPES}


def _lower_bound_ref(arr: np.ndarray, q, lo: int, hi: int) -> int:
    if hi <= lo:
        return lo
    return min(lo + int(np.searchsorted(arr[lo:hi], q, side="left")), hi - 1)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("S", SEARCH_DTYPES, ids=lambda s: s.__name__)
def test_lower_bound_every_dtype_and_range(backend, S):
    np_t = S.__kdsl_type__.np_dtype
    arr = np.array([1, 3, 3, 7, 9, 12], np_t)
    q = np.array([0, 1, 2, 3, 7, 8, 12, 100], np_t)
    lo, hi = 1, 4
    dev = device_of(backend)
    out = wp.zeros((len(q), 2), dtype=int, device=dev)
    wp.launch(SEARCH[S], dim=len(q), backend=backend, device=dev,
              inputs=[wp.array(arr, dtype=S, device=dev), wp.array(q, dtype=S, device=dev), lo, hi,
                      out])  # fmt: skip
    got = out.numpy()
    assert got[:, 0].tolist() == [_lower_bound_ref(arr, x, 0, len(arr)) for x in q]
    assert got[:, 1].tolist() == [_lower_bound_ref(arr, x, lo, hi) for x in q]
