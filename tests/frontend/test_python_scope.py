"""Python scope: builtins, standard-library functions and composite operators called from
plain Python give what the same call gives inside a kernel (kdsl/compiler/python_scope.py).

Each group's calls run twice: in Python, and in a kernel on interp (bit for bit) and on
cpu (to float32 rounding, the math library aside). Composite values behave as Warp's do
(checked against warp-lang where it is installed).
"""

import math
import pickle

import numpy as np
import pytest

import kdsl as wp
from kdsl.compiler import python_scope

BACKENDS = ["interp", "cpu"]
if wp.is_cuda_available():
    BACKENDS.append("cuda")


def _run(kernel, backend, inputs, outputs):
    """Launch ``kernel`` once on ``backend``; the outputs as NumPy arrays."""
    device = "cuda:0" if backend == "cuda" else "cpu"
    arrays = [wp.array(x, dtype=dt, device=device) for x, dt in inputs]
    outs = [wp.zeros(n, dtype=dt, device=device) for n, dt in outputs]
    wp.launch(kernel, dim=1, inputs=arrays + outs, device=device, backend=backend)
    return [o.numpy() for o in outs]


def _compare(got, want, backend):
    got = np.asarray(got)
    want = np.asarray(want)
    assert got.shape == want.shape and got.dtype == want.dtype
    if backend == "interp":
        np.testing.assert_array_equal(got.view(f"u{got.itemsize}"), want.view(f"u{want.itemsize}"))
    else:
        np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-6)


# --- scalar math ----------------------------------------------------------------------


@wp.kernel
def scalar_kernel(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    a = x[0]
    out[0] = wp.sin(a)
    out[1] = wp.sqrt(a)
    out[2] = wp.atan2(a, 0.25)
    out[3] = wp.pow(a, 1.5)
    out[4] = wp.clamp(a, 0.0, 0.5)
    out[5] = wp.floor(a * 10.0)
    out[6] = wp.exp(a) - wp.log(a)
    out[7] = wp.lerp(a, 2.0, 0.25)
    out[8] = wp.smoothstep(0.0, 1.0, a)
    out[9] = wp.abs(-a) + wp.sign(a)
    out[10] = wp.tanh(a) * wp.erf(a)
    out[11] = wp.min(a, 0.5) + wp.max(a, 0.25)


def _scalar_python(a):
    return [
        wp.sin(a), wp.sqrt(a), wp.atan2(a, 0.25), wp.pow(a, 1.5), wp.clamp(a, 0.0, 0.5),
        wp.floor(a * wp.float32(10.0)), wp.exp(a) - wp.log(a), wp.lerp(a, 2.0, 0.25),
        wp.smoothstep(0.0, 1.0, a), wp.abs(-a) + wp.sign(a), wp.tanh(a) * wp.erf(a),
        wp.min(a, 0.5) + wp.max(a, 0.25),
    ]  # fmt: skip


@pytest.mark.parametrize("backend", BACKENDS)
def test_scalar_math_matches_kernel(backend):
    x = np.float32(0.3711)
    got = _scalar_python(x)
    assert all(type(g) is np.float32 for g in got)
    (want,) = _run(scalar_kernel, backend, [([x], float)], [(12, float)])
    _compare(np.array(got, np.float32), want, backend)


@wp.kernel
def scalar64_kernel(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    a = x[0]
    out[0] = wp.sin(a)
    out[1] = wp.cbrt(a) + wp.exp2(a)
    out[2] = wp.acos(a) * wp.float64(2.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_float64_math_matches_kernel(backend):
    a = wp.float64(0.4)
    got = [wp.sin(a), wp.cbrt(a) + wp.exp2(a), wp.acos(a) * wp.float64(2.0)]
    assert all(type(g) is np.float64 for g in got)
    (want,) = _run(scalar64_kernel, backend, [([a], wp.float64)], [(3, wp.float64)])
    _compare(np.array(got), want, backend)


def test_literals_are_typed_as_in_kernels():
    # A lone float literal is f32 and an int literal i32, as in a kernel.
    assert type(wp.sin(0.5)) is np.float32
    assert wp.sin(0.5) == np.sin(np.float32(0.5))
    assert type(wp.min(1, 2)) is np.int32 and wp.min(1, 2) == 1
    assert type(wp.abs(-3)) is np.int32 and wp.abs(-3) == 3
    # Beside a typed value, a literal takes its type.
    assert type(wp.min(wp.float64(1.5), 2.0)) is np.float64
    assert wp.mul(wp.vec3d(1, 2, 3), 2.0) == wp.vec3d(2, 4, 6)
    assert type(wp.mul(wp.vec3d(1, 2, 3), 2.0)) is wp.vec3d


# --- vectors and matrices -------------------------------------------------------------


@wp.kernel
def vector_kernel(
    vs: wp.array(dtype=wp.vec3),
    ms: wp.array(dtype=wp.mat33),
    ov: wp.array(dtype=wp.vec3),
    om: wp.array(dtype=wp.mat33),
    os: wp.array(dtype=float),
):
    a = vs[0]
    b = vs[1]
    m = ms[0]
    ov[0] = wp.normalize(a)
    ov[1] = wp.cross(a, b)
    ov[2] = wp.mul(m, a)
    ov[3] = m * b
    ov[4] = a * 2.0 - b / 4.0
    ov[5] = -a + wp.cw_mul(a, b)
    om[0] = wp.transpose(m)
    om[1] = wp.outer(a, b)
    om[2] = wp.inverse(m)
    om[3] = m @ m
    os[0] = wp.dot(a, b)
    os[1] = wp.length(a)
    os[2] = wp.determinant(m)
    os[3] = wp.trace(m)


@pytest.mark.parametrize("backend", BACKENDS)
def test_vector_matrix_match_kernel(backend):
    a, b = wp.vec3(0.3, -1.25, 2.0), wp.vec3(1.5, 0.5, -0.75)
    m = wp.mat33(2.0, 0.5, 0.1, -0.3, 1.5, 0.2, 0.7, 0.1, 3.0)
    gv = [wp.normalize(a), wp.cross(a, b), wp.mul(m, a), m * b, a * 2.0 - b / 4.0,
          -a + wp.cw_mul(a, b)]  # fmt: skip
    gm = [wp.transpose(m), wp.outer(a, b), wp.inverse(m), m @ m]
    gs = [wp.dot(a, b), wp.length(a), wp.determinant(m), wp.trace(m)]
    assert all(type(v) is wp.vec3 for v in gv) and all(type(x) is wp.mat33 for x in gm)
    wv, wm, ws = _run(vector_kernel, backend, [([a, b], wp.vec3), ([m], wp.mat33)],
                      [(6, wp.vec3), (4, wp.mat33), (4, float)])  # fmt: skip
    _compare(np.array(gv), wv, backend)
    _compare(np.array(gm), wm, backend)
    _compare(np.array(gs, np.float32), ws, backend)


# --- quaternions, transforms, spatial math --------------------------------------------


@wp.kernel
def geometry_kernel(
    vs: wp.array(dtype=wp.vec3),
    oq: wp.array(dtype=wp.quat),
    ov: wp.array(dtype=wp.vec3),
    ot: wp.array(dtype=wp.transform),
    osv: wp.array(dtype=wp.spatial_vector),
):
    axis = wp.normalize(vs[0])
    p = vs[1]
    q = wp.quat_from_axis_angle(axis, 0.7)
    r = wp.quat_rpy(0.1, 0.2, 0.3)
    oq[0] = q
    oq[1] = q * r
    oq[2] = wp.normalize(q * 2.0)
    oq[3] = wp.quat_inverse(r)
    t = wp.transform(p, q)
    u = wp.transform(axis, r)
    ov[0] = wp.quat_rotate(q, p)
    ov[1] = wp.transform_point(t, axis)
    ov[2] = wp.transform_vector(t, axis)
    ov[3] = wp.transform_get_translation(t * u)
    ot[0] = t * u
    ot[1] = wp.transform_inverse(t)
    s = wp.spatial_vector(axis, p)
    osv[0] = wp.spatial_cross(s, wp.spatial_vector(p, axis))
    ov[4] = wp.spatial_top(s) + wp.spatial_bottom(s)


@pytest.mark.parametrize("backend", BACKENDS)
def test_quaternion_transform_spatial_match_kernel(backend):
    v0, p = wp.vec3(1.0, 2.0, 2.0), wp.vec3(0.5, -1.0, 3.0)
    axis = wp.normalize(v0)
    q = wp.quat_from_axis_angle(axis, 0.7)
    r = wp.quat_rpy(0.1, 0.2, 0.3)
    t, u = wp.transform(p, q), wp.transform(axis, r)
    s = wp.spatial_vector(axis, p)
    gq = [q, q * r, wp.normalize(q * 2.0), wp.quat_inverse(r)]
    gv = [wp.quat_rotate(q, p), wp.transform_point(t, axis), wp.transform_vector(t, axis),
          wp.transform_get_translation(t * u), wp.spatial_top(s) + wp.spatial_bottom(s)]  # fmt: skip
    gt = [t * u, wp.transform_inverse(t)]
    gs = [wp.spatial_cross(s, wp.spatial_vector(p, axis))]
    assert type(q * r) is wp.quat and type(t * u) is wp.transform
    wq, wv, wt, ws = _run(
        geometry_kernel, backend, [([v0, p], wp.vec3)],
        [(4, wp.quat), (5, wp.vec3), (2, wp.transform), (1, wp.spatial_vector)],
    )  # fmt: skip
    _compare(np.array(gq), wq, backend)
    _compare(np.array(gv), wv, backend)
    _compare(np.array(gt), wt, backend)
    _compare(np.array(gs), ws, backend)


# --- random numbers -------------------------------------------------------------------


@wp.kernel
def random_kernel(seeds: wp.array(dtype=int), outf: wp.array(dtype=float),
                  outi: wp.array(dtype=int), outu: wp.array(dtype=wp.uint32)):  # fmt: skip
    state = wp.rand_init(seeds[0], 7)
    outu[0] = state
    outf[0] = wp.randf(state)
    state = wp.rand_init(seeds[0], 7)
    outi[0] = wp.randi(state, 3, 17)
    state = wp.rand_init(seeds[0], 7)
    outf[1] = wp.randn(state)


@pytest.mark.parametrize("backend", BACKENDS)
def test_random_matches_kernel(backend):
    # In Python the state is passed by value: each draw starts from the same state.
    state = wp.rand_init(42, 7)
    assert type(state) is np.uint32
    got_f = [wp.randf(state), wp.randn(state)]
    got_i = [wp.randi(state, 3, 17)]
    assert wp.randf(state) == got_f[0]  # the caller's state did not advance
    wf, wi, wu = _run(random_kernel, backend, [([42], int)],
                      [(2, float), (1, int), (1, wp.uint32)])  # fmt: skip
    assert wu[0] == state
    _compare(np.array(got_f, np.float32), wf, backend)
    _compare(np.array(got_i, np.int32), wi, backend)


# --- composite values -----------------------------------------------------------------


def test_composite_values_behave_as_warp():
    v = wp.vec3(1.0, 2.0, 3.0)
    assert v == wp.vec3(1, 2, 3) and v == (1, 2, 3) and (v != (1, 2, 3)) is False
    assert (v == wp.vec3(1, 2, 4)) is False and (v == wp.vec4()) is False
    assert len(v) == 3 and list(v) == [1.0, 2.0, 3.0]
    assert tuple(v) == (1.0, 2.0, 3.0) and v.tolist() == [1.0, 2.0, 3.0]
    assert type(v[1]) is np.float32 and v[1] == 2.0 and v.y == 2.0
    assert type(v[0:2]) is wp.vec2 and v[0:2] == (1.0, 2.0)
    m = wp.mat22(1, 2, 3, 4)
    assert type(m[1]) is wp.vec2 and m[1] == (3, 4) and m[0, 1] == 2.0
    assert [type(r) for r in m] == [wp.vec2, wp.vec2] and len(m) == 2
    a = np.asarray(m)
    assert type(a) is np.ndarray and a.shape == (2, 2) and a.dtype == np.float32
    assert wp.mat22(np.array([[1, 2], [3, 4]])) == m
    t = wp.transform(wp.vec3(1, 2, 3), wp.quat_identity())
    assert type(t.p) is wp.vec3 and t.p == (1, 2, 3) and type(t.q) is wp.quat
    v.x = 5.0
    assert v == (5, 2, 3)
    assert pickle.loads(pickle.dumps(v)) == v and type(pickle.loads(pickle.dumps(v))) is wp.vec3
    # NumPy functions keep the class where the shape fits, and give plain arrays otherwise.
    assert type(np.sin(v)) is wp.vec3
    assert type(np.isnan(v)) is not wp.vec3 and not np.isnan(v).any()
    assert type(v.sum()) is np.float32
    assert repr(wp.vec2(1, 2)) == "vec2f([1.0, 2.0])"


def test_composite_operators_use_kernel_semantics():
    v, w = wp.vec3(1, 2, 3), wp.vec3(4, 5, 6)
    m = wp.mat22(1, 2, 3, 4)
    assert m * wp.vec2(1, 1) == (3, 7)  # a matrix product, not elementwise
    assert m @ m == wp.mat22(7, 10, 15, 22) and m * m == m @ m
    assert wp.vec2(1, 1) * m == (4, 6)
    assert v * w == (4, 10, 18) and v + w == (5, 7, 9) and w - v == (3, 3, 3)
    assert 2.0 * v == (2, 4, 6) and v / 2 == (0.5, 1, 1.5) and 6.0 / v == (6, 3, 2)
    assert -v == (-1, -2, -3) and +v == v
    assert wp.vec3i(7, 8, 9) / 2 == (3, 4, 4)  # integer division truncates, as in C
    q = wp.quat_from_axis_angle(wp.vec3(0, 0, 1), 0.5)
    assert q * wp.quat_inverse(q) == wp.quat_identity() or np.allclose(
        q * wp.quat_inverse(q), wp.quat_identity(), atol=1e-7
    )
    assert type(q * q) is wp.quat
    # With plain arrays or lists, NumPy's elementwise rule applies.
    assert type(v * np.ones(3)) is np.ndarray


# --- errors ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: wp.dot(wp.vec3(), wp.vec4()), r"dot\(\) needs vectors of one type.*vec<3, f32>"),
        (lambda: wp.sin(1.0, 2.0), r"sin\(\) takes 1 arguments, got 2"),
        (lambda: wp.dot(wp.vec3()), r"dot\(\) takes 2 arguments, got 1"),
        (lambda: wp.sin(x=1.0), r"sin\(\) takes no keyword"),
        (lambda: wp.sin("a"), r"kdsl.sin\(\): expected a value here, got a string"),
        (lambda: wp.quat_rotate(wp.vec3(), wp.vec3()),
         r"no overload of quat_rotate\(\) takes \(vec<3, f32>, vec<3, f32>\)"),
        (lambda: wp.normalize(np.zeros(3)),
         r"kdsl.normalize\(\): argument 1 is a NumPy array of shape \(3,\)"),
        (lambda: wp.length([1.0, 2.0]), r"argument 1 is a Python list"),
        (lambda: wp.vec3() + wp.vec4(), r"cannot add vec<3, f32> and vec<4, f32>"),
        (lambda: wp.vec3() * wp.mat22(), r"cannot multiply vec<3, f32> by mat<2, 2, f32>"),
        (lambda: wp.vec3d() + wp.vec3(), r"cannot add vec<3, f64> and vec<3, f32>"),
        (lambda: wp.tid(), r"kdsl.tid\(\) reads or writes arrays or the thread index"),
        (lambda: wp.atomic_add(1, 2, 3), r"kernel builtin only"),
        (lambda: wp.vec3(1, 2), r"vec3f takes 3 components, got 2"),
    ],
)  # fmt: skip
def test_errors_say_what_was_expected(call, message):
    with pytest.raises(wp.KdslError, match=message) as info:
        call()
    assert info.value.loc is None  # never the generated caller's location
    assert "python scope" not in str(info.value)


def test_user_functions_run_as_python():
    # As in Warp, a user's @func called from Python runs as a plain Python function.
    calls = []

    @wp.func
    def twice(x: float) -> float:
        calls.append(x)
        return x * 2.0

    assert twice(1.5) == 3.0 and calls == [1.5]


# --- the cache ------------------------------------------------------------------------


def test_compiled_once_per_types():
    v = wp.vec3(3, 4, 12)
    wp.length(v * 1.0)  # compiles length(vec3) and vec3 * float once, whatever ran before
    before = len(python_scope._cache)
    for k in range(5):
        assert wp.length(v * float(k + 1)) == 13.0 * (k + 1)
    assert len(python_scope._cache) == before  # same types: no new compile
    wp.length(wp.vec3d(3, 4, 12))
    assert len(python_scope._cache) == before + 1
    # A literal is a parameter: new values reuse the compiled function.
    wp.cos(0.25)
    before = len(python_scope._cache)
    for x in (0.5, 0.7, -3.25):
        assert wp.cos(x) == np.cos(np.float32(x))
    assert len(python_scope._cache) == before


def test_literals_read_at_compile_time_are_cached_per_value():
    # identity(n=...) reads its literal while compiling: one function per value.
    assert wp.identity(n=2, dtype=float) == wp.mat22(1, 0, 0, 1)
    assert wp.identity(n=3, dtype=float) == wp.mat33(1, 0, 0, 0, 1, 0, 0, 0, 1)
    # -0.0 and 0.0 are different literals, even where one function serves each value.
    assert wp.atan2(0.0, -1.0) == np.float32(math.pi)
    assert wp.atan2(-0.0, -1.0) == -np.float32(math.pi)
    assert math.copysign(1.0, wp.copysign(1.0, -0.0)) == -1.0
    assert math.copysign(1.0, wp.copysign(1.0, 0.0)) == 1.0


# --- against Warp ---------------------------------------------------------------------

WARP_CASES = [
    "wp.normalize(wp.vec3(1.0, 2.0, 2.0))",
    "wp.dot(wp.vec3(1.0, 2.0, 3.0), wp.vec3(4.0, 5.0, 6.0))",
    "wp.quat_rotate(wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), 0.5), wp.vec3(1.0, 0.0, 0.0))",
    "wp.quat_from_axis_angle(wp.vec3(0.0, 1.0, 0.0), 1.25)",
    "wp.transform_point(wp.transform(wp.vec3(1.0, 2.0, 3.0), wp.quat_rpy(0.1, 0.2, 0.3)),"
    " wp.vec3(1.0, 1.0, 1.0))",
    "wp.mul(wp.mat22(1.0, 2.0, 3.0, 4.0), wp.vec2(1.0, -1.0))",
    "wp.transpose(wp.mat22(1.0, 2.0, 3.0, 4.0))",
    "wp.mat22(1.0, 2.0, 3.0, 4.0) * wp.vec2(1.0, -1.0)",
    "wp.mat22(1.0, 2.0, 3.0, 4.0) @ wp.mat22(0.5, 2.0, 3.0, 4.0)",
    "wp.quat_rpy(0.1, 0.2, 0.3) * wp.quat_rpy(0.3, 0.2, 0.1)",
    "wp.transform(wp.vec3(1.0, 2.0, 3.0), wp.quat_rpy(0.1, 0.2, 0.3))"
    " * wp.transform(wp.vec3(-1.0, 0.5, 0.0), wp.quat_rpy(0.3, 0.2, 0.1))",
    "wp.vec3(1.0, 2.0, 3.0) == wp.vec3(1.0, 2.0, 3.0)",
    "wp.vec3(1.0, 2.0, 3.0) != wp.vec3(1.0, 2.0, 3.0)",
    "wp.vec3(1.0, 2.0, 3.0) * 2.0",
    "-wp.vec3(1.0, 2.0, 3.0)",
    "wp.vec3i(1, 2, 3) / 2",
    "len(wp.mat33())",
    "tuple(wp.vec3(1.0, 2.0, 3.0))",
    "wp.mat22(1.0, 2.0, 3.0, 4.0)[1]",
    "wp.mat22(1.0, 2.0, 3.0, 4.0)[0, 1]",
    "wp.vec4(1.0, 2.0, 3.0, 4.0)[1:3]",
    "wp.sin(0.5)",
    "wp.clamp(5, 0, 3)",
    "wp.randf(wp.rand_init(1))",
    "wp.max(wp.vec3(1.0, 5.0, 3.0))",
    "wp.spatial_top(wp.spatial_vector(1.0, 2.0, 3.0, 4.0, 5.0, 6.0))",
]


@pytest.mark.parametrize("expr", WARP_CASES)
def test_matches_warp(expr):
    warp = pytest.importorskip("warp")
    warp.config.quiet = True
    want = eval(expr, {"wp": warp})
    got = eval(expr, {"wp": wp})
    if isinstance(want, bool):
        assert got is want
        return
    if isinstance(want, tuple):
        assert isinstance(got, tuple)
    got_a = np.array(got, dtype=np.float64)
    want_a = np.array(want, dtype=np.float64).reshape(got_a.shape)
    np.testing.assert_allclose(got_a, want_a, rtol=1e-6, atol=1e-7)
    name = type(want).__name__
    if np.ndim(got) and not name.endswith("_t"):  # Warp names a slice's class vec_t
        assert type(got).__name__ == name
