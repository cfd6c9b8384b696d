"""Quaternions, transforms and spatial algebra: kdsl against Warp 1.19 and NumPy.

The Warp comparison writes one kernel source, imports it once with ``wp = kdsl``
and once with ``wp = warp`` (which runs on the CPU here), launches both on the
same inputs (random rotations plus edge rows: identity, 180-degree turns,
antipodal pairs, zero vectors) and compares every output. It is skipped where
warp is not installed (CI). The NumPy checks and the frontend tests always run.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import kdsl
from kdsl.errors import KdslTypeError
from tests.warp_peer import import_warp_cpu

N = 12

# One kernel per dtype: {F} is the scalar type name, {s} the class suffix ("" or "d").
_GENERIC = """
import {MOD} as wp

@wp.kernel
def geom_{F}(qa: wp.array(dtype=wp.quat{s}), qb: wp.array(dtype=wp.quat{s}),
             qraw: wp.array(dtype=wp.quat{s}), va: wp.array(dtype=wp.vec3{s}),
             vb: wp.array(dtype=wp.vec3{s}), sc: wp.array(dtype=wp.{F}),
             rot: wp.array(dtype=wp.mat33{s}),
             oq: wp.array2d(dtype=wp.quat{s}), ov: wp.array2d(dtype=wp.vec3{s}),
             os: wp.array2d(dtype=wp.{F}), ot: wp.array2d(dtype=wp.transform{s}),
             om: wp.array2d(dtype=wp.mat44{s}), om3: wp.array2d(dtype=wp.mat33{s}),
             osv: wp.array2d(dtype=wp.spatial_vector{s}),
             osm: wp.array2d(dtype=wp.spatial_matrix{s})):
    i = wp.tid()
    a = qa[i]
    b = qb[i]
    u = va[i]
    v = vb[i]
    s = sc[i]
    ta = wp.transform{s}(u, a)
    tb = wp.transform{s}(v, b)
    oq[i, 0] = wp.quat_from_axis_angle(wp.normalize(u), s)
    oq[i, 1] = a * b
    oq[i, 2] = a * s
    oq[i, 3] = wp.quat_inverse(a)
    oq[i, 4] = wp.quat_rpy(u[0], u[1], u[2])
    oq[i, 5] = wp.quat_slerp(a, b, s)
    oq[i, 6] = wp.quat_from_matrix(rot[i])
    oq[i, 7] = wp.quat_from_matrix(wp.transform_to_matrix(ta))
    oq[i, 8] = wp.normalize(qraw[i])
    oq[i, 9] = wp.normalize(qraw[i] * wp.{F}(0.0))
    oq[i, 10] = wp.quat_identity(dtype=wp.{F})
    oq[i, 11] = wp.mul(b, a)
    oq[i, 12] = -a + b * wp.{F}(2.0) - a / wp.{F}(4.0)
    ov[i, 0] = wp.quat_rotate(a, v)
    ov[i, 1] = wp.quat_rotate_inv(a, v)
    axis, angle = wp.quat_to_axis_angle(a)
    ov[i, 2] = axis
    ov[i, 3] = wp.transform_point(ta, v)
    ov[i, 4] = wp.transform_vector(ta, v)
    m = wp.transform_to_matrix(ta)
    ov[i, 5] = wp.transform_point(m, v)
    ov[i, 6] = wp.transform_vector(m, v)
    ov[i, 7] = ta.p
    pos, r, scale = wp.transform_decompose(wp.transform_compose(u, a, v))
    ov[i, 8] = pos
    ov[i, 9] = scale
    oq[i, 13] = r
    os[i, 0] = angle
    os[i, 1] = wp.dot(a, b)
    os[i, 2] = wp.length(qraw[i])
    os[i, 3] = wp.length_sq(qraw[i])
    ot[i, 0] = ta * tb
    ot[i, 1] = wp.transform_multiply(tb, ta)
    ot[i, 2] = wp.transform_inverse(ta)
    ot[i, 3] = wp.transform_identity(dtype=wp.{F})
    ot[i, 4] = wp.transform_from_matrix(m)
    x = ta
    wp.transform_set_translation(x, v)
    wp.transform_set_rotation(x, b)
    ot[i, 5] = x
    y = ta
    y.p = v
    y.q = b
    y.p += u
    ot[i, 6] = y
    ot[i, 7] = ta * s
    ot[i, 8] = wp.transformation(u, a)
    ot[i, 9] = wp.transformation(u)
    oq[i, 15] = wp.quaternion(u, s)
    oq[i, 14] = wp.transform_get_rotation(tb)
    ov[i, 10] = wp.transform_get_translation(tb)
    om[i, 0] = m
    om[i, 1] = wp.transform_compose(u, a, v)
    om3[i, 0] = wp.quat_to_matrix(a)
    w = wp.quat_rotate(b, u)
    sa = wp.spatial_vector{s}(u[0], u[1], u[2], v[0], v[1], v[2])
    sb = wp.spatial_vector{s}(v[0], v[1], v[2], w[0], w[1], w[2])
    osv[i, 0] = wp.spatial_cross(sa, sb)
    osv[i, 1] = wp.spatial_cross_dual(sa, sb)
    bot = wp.spatial_bottom(sa)
    top = wp.spatial_top(sb)
    osv[i, 2] = wp.spatial_vector{s}(bot[0], bot[1], bot[2], top[0], top[1], top[2])
    os[i, 4] = wp.spatial_dot(sa, sb)
    osm[i, 0] = wp.spatial_adjoint(wp.quat_to_matrix(a), wp.outer(u, v))
"""

# Functions Warp defines for float32 only (kdsl has every float dtype).
_F32_ONLY = """
import {MOD} as wp

@wp.kernel
def geom32(qa: wp.array(dtype=wp.quat), va: wp.array(dtype=wp.vec3),
           vb: wp.array(dtype=wp.vec3), ov: wp.array2d(dtype=wp.vec3),
           oq: wp.array2d(dtype=wp.quat), os: wp.array2d(dtype=float),
           osv: wp.array2d(dtype=wp.spatial_vector)):
    i = wp.tid()
    a = qa[i]
    u = va[i]
    v = vb[i]
    ov[i, 0] = wp.quat_to_rpy(a)
    ov[i, 1] = wp.quat_to_euler(a, 0, 1, 2)
    ov[i, 2] = wp.quat_to_euler(a, 2, 1, 0)
    ov[i, 3] = wp.quat_to_euler(a, 1, 0, 2)
    ov[i, 4] = wp.quat_to_euler(a, 0, 1, 0)
    ov[i, 5] = wp.quat_to_euler(a, 2, 0, 2)
    oq[i, 0] = wp.quat_from_euler(u, 0, 1, 2)
    oq[i, 1] = wp.quat_from_euler(u, 2, 0, 1)
    oq[i, 2] = wp.quat_from_euler(u, 1, 2, 1)
    oq[i, 3] = wp.quat_twist(wp.normalize(v), a)
    os[i, 0] = wp.quat_twist_angle(wp.normalize(v), a)
    os[i, 1] = wp.quat_twist_angle_signed(wp.normalize(v), a)
    t = wp.transform(v, a)
    sa = wp.spatial_vector(u, v)
    osv[i, 0] = wp.transform_twist(t, sa)
    osv[i, 1] = wp.transform_wrench(t, sa)
    ov[i, 6] = wp.velocity_at_point(sa, u)
"""

_SLOTS = {"oq": 16, "ov": 11, "os": 5, "ot": 10, "om": 2, "om3": 1, "osv": 3, "osm": 1}
_SLOTS32 = {"ov": 7, "oq": 4, "os": 2, "osv": 2}


def _rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions (x, y, z, w), float64."""
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)  # fmt: skip


def _inputs(np_dtype) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    qa, qb = _rotations(rng, N), _rotations(rng, N)
    va, vb = rng.uniform(-2, 2, (N, 3)), rng.uniform(-2, 2, (N, 3))
    sc = rng.uniform(0, 1, N)
    # Edge rows: identity vs. its antipode; 180-degree turns; a zero axis; t at 0 and 1.
    qa[0], qb[0], va[0], sc[0] = (0, 0, 0, 1), (0, 0, 0, -1), (0, 0, 0), 0.0
    qa[1], qb[1], sc[1] = (1, 0, 0, 0), (0, 1, 0, 0), 1.0
    qa[2], qb[2], sc[2] = (0, 0, 1, 0), (0, 0, -1, 0), 0.5
    qa[3], qb[3] = qa[4], -qa[4]
    qraw = rng.normal(size=(N, 4)) * 3
    rot_q = _rotations(rng, N)
    rot_q[0], rot_q[1], rot_q[2] = (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0)  # trace -1 paths
    data = dict(qa=qa, qb=qb, qraw=qraw, va=va, vb=vb, sc=sc, rot=_quat_matrix(rot_q))
    return {k: v.astype(np_dtype) for k, v in data.items()}


def _load(tmp_path: Path, mod: str, source: str, tag: str):
    path = tmp_path / f"geom_{mod}_{tag}.py"
    path.write_text(source.replace("{MOD}", mod))
    name = f"_geom_{mod}_{tag}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


_SHAPES = {"oq": (4,), "ov": (3,), "os": (), "ot": (7,), "om": (4, 4), "om3": (3, 3),
           "osv": (6,), "osm": (6, 6)}  # fmt: skip


def _run(lib, kernel, inputs: dict, slots: dict, dtype, backend=None) -> dict[str, np.ndarray]:
    """Launch ``kernel`` of library ``lib`` (kdsl or warp) on the CPU; its outputs."""
    outs = {name: np.zeros((N, k, *_SHAPES[name]), dtype) for name, k in slots.items()}
    arrays = {name: lib.array(a, dtype=_array_dtype(lib, name, a), device="cpu")
              for name, a in {**inputs, **outs}.items()}  # fmt: skip
    code = kernel.func.__code__
    params = code.co_varnames[: code.co_argcount]
    kwargs = {"backend": backend} if backend else {}
    lib.launch(kernel, dim=N, inputs=[arrays[p] for p in params], device="cpu", **kwargs)
    return {name: arrays[name].numpy() for name in outs}


def _array_dtype(lib, name: str, a: np.ndarray):
    s = "d" if a.dtype == np.float64 else ""
    comp = {"qa": "quat", "qb": "quat", "qraw": "quat", "oq": "quat", "va": "vec3", "vb": "vec3",
            "ov": "vec3", "rot": "mat33", "om3": "mat33", "om": "mat44", "ot": "transform",
            "osv": "spatial_vector", "osm": "spatial_matrix"}.get(name)  # fmt: skip
    if comp is None:
        return lib.float64 if s else lib.float32
    return getattr(lib, comp + s)


def _compare(got: dict, want: dict, rtol: float, atol: float) -> None:
    for name in want:
        np.testing.assert_allclose(got[name], want[name], rtol=rtol, atol=atol, err_msg=name)


@pytest.fixture(scope="module")
def warp():
    return import_warp_cpu()


@pytest.mark.parametrize("F", ["float32", "float64"])
def test_matches_warp(warp, tmp_path, F):
    np_dtype = np.dtype(F)
    src = _GENERIC.replace("{F}", F).replace("{s}", "d" if F == "float64" else "")
    ours = _load(tmp_path, "kdsl", src, F)
    theirs = _load(tmp_path, "warp", src, F)
    inputs = _inputs(np_dtype)
    want = _run(warp, getattr(theirs, f"geom_{F}"), inputs, _SLOTS, np_dtype)
    tol = (2e-5, 2e-5) if F == "float32" else (1e-12, 1e-12)
    for backend in ("cpu", "interp"):
        got = _run(kdsl, getattr(ours, f"geom_{F}"), inputs, _SLOTS, np_dtype, backend)
        _compare(got, want, *tol)


def test_matches_warp_float32_only_functions(warp, tmp_path):
    ours = _load(tmp_path, "kdsl", _F32_ONLY, "f32only")
    theirs = _load(tmp_path, "warp", _F32_ONLY, "f32only")
    inputs = {k: v for k, v in _inputs(np.float32).items() if k in ("qa", "va", "vb")}
    want = _run(warp, theirs.geom32, inputs, _SLOTS32, np.float32)
    for backend in ("cpu", "interp"):
        got = _run(kdsl, ours.geom32, inputs, _SLOTS32, np.float32, backend)
        _compare(got, want, 3e-5, 3e-5)


# --- frontend behaviour (no warp needed) ----------------------------------------------


@kdsl.kernel
def k_ops(q: kdsl.array(dtype=kdsl.quat), t: kdsl.array(dtype=kdsl.transform),
          out_q: kdsl.array(dtype=kdsl.quat), out_t: kdsl.array(dtype=kdsl.transform)):  # fmt: skip
    i = kdsl.tid()
    out_q[i] = q[i] * q[i]
    out_t[i] = t[i] * t[i]


def test_products_call_the_library(build_text, check_ir):
    # q * q and t * t are calls of library code (no new op); q * s stays an arith.mul.
    check_ir(
        build_text(k_ops),
        """
        CHECK: func.call %0, %1 {callee = "quat_multiply_{{.*}}"} : quat<f32>
        CHECK: func.call %3, %4 {callee = "transform_multiply_{{.*}}"} : transform<f32>
        CHECK: func.func @quat_multiply_
        CHECK: func.func @transform_multiply_
        """,
    )


def _compile(body: str, tmp_path: Path, params: str = "q: wp.array(dtype=wp.quat)"):
    src = f"import kdsl as wp\n\n@wp.kernel\ndef k({params}):\n    i = wp.tid()\n{body}"
    return _load(tmp_path, "kdsl", src, f"err{abs(hash(body))}").k.build_module


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("    x = q[i] * wp.vec3(1.0)\n", "cannot multiply"),
        ("    x = wp.mat44(1.0) * q[i]\n", "by quat<f32>"),
        ("    x = q[i] * wp.quatd(q[i])\n", "cannot multiply"),
        ("    x = wp.quat_identity(dtype=wp.int32)\n", "float dtype"),
        ("    x = wp.quat_identity(wp.float32, dtype=wp.float32)\n", "dtype twice"),
        ("    x = wp.quat_rotate(q[i], wp.vec3d(1.0))\n", "no overload of quat_rotate"),
        ("    t = wp.transform_identity()\n    t.p = 1.0\n", "transform_set_translation_copy"),
        ("    t = wp.transform_identity()\n    t.r = q[i]\n", "has no attribute '.r'"),
    ],
)
def test_located_type_errors(tmp_path, body, message):
    with pytest.raises(KdslTypeError, match=message) as info:
        _compile(body, tmp_path)()
    assert info.value.loc is not None and info.value.loc.line >= 5


def test_literal_arguments_pick_float32_and_half_works():
    @kdsl.kernel
    def k(out: kdsl.array(dtype=kdsl.quat), h: kdsl.array(dtype=kdsl.vec3h)):
        out[0] = kdsl.quat_rpy(0.1, 0.2, 0.3)
        qh = kdsl.quat_from_axis_angle(kdsl.vec3h(0.0, 0.0, 1.0), kdsl.float16(1.5707964))
        h[0] = kdsl.quat_rotate(qh, kdsl.vec3h(1.0, 0.0, 0.0))

    for backend in ("interp", "cpu"):
        out = kdsl.zeros(1, dtype=kdsl.quat)
        h = kdsl.zeros(1, dtype=kdsl.vec3h)
        kdsl.launch(k, 1, [out, h], backend=backend)
        cr, sr, cp, sp, cy, sy = (f(a / 2) for a in (0.1, 0.2, 0.3) for f in (math.cos, math.sin))
        want = [sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy]  # fmt: skip
        np.testing.assert_allclose(out.numpy()[0], want, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(h.numpy()[0], [0, 1, 0], atol=2e-3)


def test_set_translation_writes_back_only_to_variables():
    @kdsl.kernel
    def k(ts: kdsl.array(dtype=kdsl.transform), out: kdsl.array(dtype=kdsl.transform)):
        i = kdsl.tid()
        x = ts[i]
        kdsl.transform_set_translation(x, kdsl.vec3(1.0, 2.0, 3.0))
        kdsl.transform_set_rotation(ts[i], kdsl.quat(0.0, 0.0, 1.0, 0.0))  # a temporary
        out[i] = x

    ts = kdsl.array(
        np.tile([9, 9, 9, 0, 0, 0, 1.0], (2, 1)).astype(np.float32), dtype=kdsl.transform
    )
    for backend in ("interp", "cpu"):
        out = kdsl.zeros(2, dtype=kdsl.transform)
        kdsl.launch(k, 2, [ts, out], backend=backend)
        np.testing.assert_array_equal(out.numpy(), [[1, 2, 3, 0, 0, 0, 1]] * 2)
        np.testing.assert_array_equal(ts.numpy(), [[9, 9, 9, 0, 0, 0, 1]] * 2)


@kdsl.kernel
def k_grad(
    q: kdsl.array(dtype=kdsl.quatd),
    v: kdsl.array(dtype=kdsl.vec3d),
    loss: kdsl.array(dtype=kdsl.float64),
):
    i = kdsl.tid()
    t = kdsl.transformd(v[i], kdsl.normalize(q[i]))
    p = kdsl.transform_point(t * t, kdsl.quat_rotate(q[i], v[i]))
    kdsl.atomic_add(loss, 0, kdsl.dot(p, p) + kdsl.quat_to_rpy(kdsl.normalize(q[i]))[1])


def test_gradients_flow_through_the_library():
    # The library is plain kdsl code, so reverse mode differentiates it like user code.
    rng = np.random.default_rng(3)
    q0, v0 = rng.normal(size=(3, 4)), rng.normal(size=(3, 3))

    def run(qn):
        q = kdsl.array(qn, dtype=kdsl.quatd, requires_grad=True)
        v = kdsl.array(v0, dtype=kdsl.vec3d, requires_grad=True)
        loss = kdsl.zeros(1, dtype=kdsl.float64, requires_grad=True)
        tape = kdsl.Tape()
        with tape:
            kdsl.launch(k_grad, 3, [q, v, loss], backend="cpu")
        tape.backward(loss)
        return loss.numpy()[0], q.grad.numpy()

    _, grad = run(q0)
    eps = 1e-6
    fd = np.zeros_like(q0)
    for idx in np.ndindex(q0.shape):
        hi, lo = q0.copy(), q0.copy()
        hi[idx] += eps
        lo[idx] -= eps
        fd[idx] = (run(hi)[0] - run(lo)[0]) / (2 * eps)
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6)


def test_constructors_in_kernels():
    @kdsl.kernel
    def k(t: kdsl.array(dtype=kdsl.transformd), q: kdsl.array(dtype=kdsl.quatd)):
        t[0] = kdsl.transformation(kdsl.vec3d(1.0, 2.0, 3.0))
        t[1] = kdsl.transformation(1.0, 2.0, 3.0, 0.0, 1.0, 0.0, 0.0, dtype=kdsl.float64)
        t[2] = kdsl.transform_identity(kdsl.float64) * kdsl.transformation(dtype=kdsl.float64)
        q[0] = kdsl.quaternion(kdsl.vec3d(1.0, 2.0, 3.0), 4.0, dtype=kdsl.float64)
        q[1] = kdsl.quaternion(kdsl.quat_identity(), dtype=kdsl.float64) * kdsl.quat_identity(
            dtype=kdsl.float64
        )

    for backend in ("interp", "cpu"):
        t = kdsl.zeros(3, dtype=kdsl.transformd)
        q = kdsl.zeros(2, dtype=kdsl.quatd)
        kdsl.launch(k, 1, [t, q], backend=backend)
        want_t = [[1, 2, 3, 0, 0, 0, 1], [1, 2, 3, 0, 1, 0, 0], [0, 0, 0, 0, 0, 0, 0]]
        np.testing.assert_array_equal(t.numpy(), want_t)
        np.testing.assert_array_equal(q.numpy(), [[1, 2, 3, 4], [0, 0, 0, 1]])
