"""Random numbers and noise: in-out ``state``, Warp bit-exactness, statistics.

The Warp comparisons import one kernel source twice, once as ``kdsl`` and once
as ``warp`` (1.19, run on the CPU), and compare the outputs. They are skipped
when warp is not installed.
"""

import importlib.util
import sys

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslSyntaxError, KdslTypeError
from kdsl.testing import random_ref as R
from tests.warp_peer import import_warp_cpu

N = 64

# --- the in-out state -----------------------------------------------------------------


@wp.func
def two_draws(state: wp.inout(wp.uint32)) -> float:
    return wp.randf(state) + 2.0 * wp.randf(state)


@wp.func
def by_value(state: wp.uint32) -> float:
    return wp.randf(state)


@wp.kernel
def k_inout(seed: wp.array(dtype=wp.int32), states: wp.array(dtype=wp.uint32),
            out: wp.array(dtype=float, ndim=2), final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    out[i, 0] = wp.randf(state)  # advances state
    out[i, 1] = wp.randf(state)
    out[i, 2] = by_value(state)  # reads state, leaves it
    out[i, 3] = two_draws(state)  # advances it twice
    for _k in range(3):  # carried through the loop
        out[i, 4] += wp.randf(state)
    n = 0
    while wp.randf(state) < 0.5 and n < 50:  # advanced by the test itself
        n += 1
    out[i, 5] = float(n)
    out[i, 6] = wp.randf(states[i])  # an array element is a temporary
    final[i] = state


def _inout_ref(seed):
    s = R.Stream(R.rand_init(seed))
    out = np.zeros((len(seed), 7), np.float32)
    out[:, 0] = s.randf()
    out[:, 1] = s.randf()
    out[:, 2] = R.Stream(s.state).randf()
    a, b = s.randf(), s.randf()
    out[:, 3] = a + np.float32(2.0) * b
    for _ in range(3):
        out[:, 4] += s.randf()
    final = np.zeros(len(seed), np.uint32)
    for i in range(len(seed)):
        one = R.Stream(s.state[i : i + 1])
        n = 0
        while one.randf()[0] < 0.5 and n < 50:
            n += 1
        out[i, 5] = n
        final[i] = one.state[0]
    return out, final


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_inout_state_advances_like_warp(backend):
    seed = np.arange(-8, 8, dtype=np.int32) * 7919
    states = R.rand_init(seed + 1)
    out = wp.zeros((16, 7), dtype=float)
    final = wp.zeros(16, dtype=wp.uint32)
    st = wp.from_numpy(states)
    wp.launch(k_inout, 16, [wp.from_numpy(seed), st, out, final], backend=backend)
    want, want_final = _inout_ref(seed)
    want[:, 6] = R.Stream(states).randf()
    np.testing.assert_allclose(out.numpy(), want, rtol=1e-6)
    np.testing.assert_array_equal(final.numpy(), want_final)
    np.testing.assert_array_equal(st.numpy(), states)  # never written back


def test_inout_is_an_extra_result_in_the_ir(build_text, check_ir):
    text = build_text(k_inout)
    # randf(state) returns (value, new state); the by-value function returns one value.
    check_ir(text, """
        CHECK: func.call {{.*}}callee = "randf_{{.*}} : f32, u32
        CHECK: func.call {{.*}}callee = "by_value_{{.*}} : f32
        CHECK: func.func @randf_{{.*}} -> (f32, u32)
    """)  # fmt: skip


def test_kernel_cannot_take_inout():
    @wp.kernel
    def bad(state: wp.inout(wp.uint32), out: wp.array(dtype=float)):
        out[0] = wp.randf(state)

    with pytest.raises(KdslSyntaxError, match="inout"):
        bad.build_module()


def test_state_must_be_uint32():
    @wp.kernel
    def bad(out: wp.array(dtype=float)):
        state = 5
        out[0] = wp.randf(state)

    with pytest.raises(KdslTypeError, match="randf"):
        bad.build_module()


def test_literal_and_expression_states_are_temporaries():
    @wp.kernel
    def k(out: wp.array(dtype=float)):
        out[0] = wp.randf(wp.uint32(7))
        out[1] = wp.randf(wp.rand_init(3) + wp.uint32(0))
        out[2] = wp.randf(wp.rand_init(3))

    out = wp.zeros(3, dtype=float)
    wp.launch(k, 1, [out], backend="interp")
    got = out.numpy()
    assert got[0] == R.Stream(np.array([7], np.uint32)).randf()[0]
    assert got[1] == got[2] == R.Stream(R.rand_init(np.array([3]))).randf()[0]


# --- statistics -------------------------------------------------------------------------

DRAWS = 1 << 16


@wp.kernel
def k_stats(seed: int, u: wp.array(dtype=float), g: wp.array(dtype=float),
            k: wp.array(dtype=wp.int32), p: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed, i)
    u[i] = wp.randf(state)
    g[i] = wp.randn(state)
    k[i] = wp.randi(state, 0, 10)
    p[i] = wp.poisson(state, wp.select(i % 2 == 0, 40.0, 3.5))  # (cond, if false, if true)


def test_distributions():
    u, g = wp.zeros(DRAWS, dtype=float), wp.zeros(DRAWS, dtype=float)
    k, p = wp.zeros(DRAWS, dtype=wp.int32), wp.zeros(DRAWS, dtype=wp.uint32)
    wp.launch(k_stats, DRAWS, [2024, u, g, k, p], backend="cpu")
    u, g, k, p = u.numpy(), g.numpy(), k.numpy(), p.numpy().astype(np.float64)
    se = 1.0 / np.sqrt(DRAWS)
    assert u.min() >= 0.0 and u.max() < 1.0
    assert abs(u.mean() - 0.5) < 5 * se * np.sqrt(1 / 12)
    assert abs(u.var() - 1 / 12) < 5 * se * np.sqrt(1 / 180)
    assert abs(g.mean()) < 5 * se and abs(g.var() - 1.0) < 5 * se * np.sqrt(2.0)
    assert abs(np.mean(np.abs(g) < 1.0) - 0.6827) < 0.01
    counts = np.bincount(k, minlength=10)
    assert counts.size == 10
    chi2 = np.sum((counts - DRAWS / 10) ** 2 / (DRAWS / 10))
    assert chi2 < 27.9  # the 0.001 tail of chi-square with 9 degrees of freedom
    for lam, sample in ((3.5, p[0::2]), (40.0, p[1::2])):
        sd = np.sqrt(lam / sample.size)
        assert abs(sample.mean() - lam) < 5 * sd
        assert abs(sample.var() / lam - 1.0) < 0.05
    # Neighbouring threads' streams are uncorrelated.
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 5 * se


# --- bit-exactness against Warp -----------------------------------------------------------

KERNELS = '''
import {api} as wp


@wp.kernel
def draws(seed: wp.array(dtype=wp.int32), offset: wp.array(dtype=wp.int32),
          lo: wp.array(dtype=wp.int32), hi: wp.array(dtype=wp.int32),
          lam: wp.array(dtype=float), cdf: wp.array(dtype=float),
          ints: wp.array(dtype=wp.int32, ndim=2), uints: wp.array(dtype=wp.uint32, ndim=2),
          exact: wp.array(dtype=float, ndim=2), libm: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    s = wp.rand_init(seed[i], offset[i])
    uints[i, 0] = wp.rand_init(seed[i])
    uints[i, 1] = s
    ints[i, 0] = wp.randi(s)
    ints[i, 1] = wp.randi(s, lo[i], hi[i])
    ints[i, 2] = wp.sample_cdf(s, cdf)
    uints[i, 2] = wp.randu(s)
    uints[i, 3] = wp.randu(s, wp.uint32(lo[i]), wp.uint32(hi[i]))
    uints[i, 4] = wp.poisson(s, lam[i])
    uints[i, 5] = wp.poisson(s, 20.0 * lam[i])
    exact[i, 0] = wp.randf(s)
    exact[i, 1] = wp.randf(s, -3.0, 7.5)
    t = wp.sample_triangle(s)
    q = wp.sample_unit_square(s)
    c = wp.sample_unit_cube(s)
    exact[i, 2] = t[0]
    exact[i, 3] = t[1]
    exact[i, 4] = q[0]
    exact[i, 5] = q[1]
    exact[i, 6] = c[0]
    exact[i, 7] = c[2]
    libm[i, 0] = wp.randn(s)
    r = wp.sample_unit_ring(s)
    d = wp.sample_unit_disk(s)
    a = wp.sample_unit_sphere_surface(s)
    b = wp.sample_unit_sphere(s)
    e = wp.sample_unit_hemisphere_surface(s)
    f = wp.sample_unit_hemisphere(s)
    libm[i, 1] = r[0]
    libm[i, 2] = d[1]
    libm[i, 3] = a[0]
    libm[i, 4] = a[2]
    libm[i, 5] = b[1]
    libm[i, 6] = e[2]
    libm[i, 7] = f[0]
    uints[i, 6] = s


@wp.kernel
def noise1(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=float),
           out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    s = wp.rand_init(seed[i])
    out[i, 0] = wp.noise(s, x[i])
    out[i, 1] = wp.pnoise(s, wp.abs(x[i]), 3)


@wp.kernel
def noise2(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec2),
           out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    s = wp.rand_init(seed[i])
    out[i, 0] = wp.noise(s, x[i])
    out[i, 1] = wp.pnoise(s, wp.vec2(wp.abs(x[i][0]), wp.abs(x[i][1])), 3, 5)


@wp.kernel
def noise3(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec3),
           out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    s = wp.rand_init(seed[i])
    p = x[i]
    out[i, 0] = wp.noise(s, p)
    out[i, 1] = wp.pnoise(s, wp.vec3(wp.abs(p[0]), wp.abs(p[1]), wp.abs(p[2])), 2, 7, 4)


@wp.kernel
def noise4(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec4),
           out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    s = wp.rand_init(seed[i])
    p = x[i]
    out[i, 0] = wp.noise(s, p)
    out[i, 1] = wp.pnoise(s, wp.vec4(wp.abs(p[0]), wp.abs(p[1]), wp.abs(p[2]), wp.abs(p[3])),
                          5, 1, 3, 6)


@wp.kernel
def curl2(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec2),
          out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    out[i] = wp.curlnoise(wp.rand_init(seed[i]), x[i], wp.uint32(3), 2.0, 0.5)


@wp.kernel
def curl3(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec3),
          out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = wp.curlnoise(wp.rand_init(seed[i]), x[i], wp.uint32(2), 1.9, 0.6)


@wp.kernel
def curl4(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec4),
          out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = wp.curlnoise(wp.rand_init(seed[i]), x[i], wp.uint32(1), 2.0, 0.5)
'''


def _import_kernels(api: str, tmp_path_factory):
    path = tmp_path_factory.mktemp(f"kernels_{api}") / f"random_kernels_{api}.py"
    path.write_text(KERNELS.format(api=api))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def apis(tmp_path_factory):
    """(kdsl kernels, warp module, warp kernels); skipped without warp."""
    warp = import_warp_cpu()
    return (_import_kernels("kdsl", tmp_path_factory), warp,
            _import_kernels("warp", tmp_path_factory))  # fmt: skip


def _run_both(apis, name, dim, inputs, outputs):
    """Launch kernel ``name`` with kdsl (cpu) and with warp (cpu); gives both outputs."""
    kd, warp, wk = apis
    got = {}
    for api, mod in (("kdsl", kd), ("warp", wk)):
        lib = wp if api == "kdsl" else warp
        args = [lib.array(a, dtype=_dtype(lib, t), device="cpu") for a, t in inputs]
        outs = [lib.zeros(shape, dtype=_dtype(lib, t), device="cpu") for shape, t in outputs]
        kw = {"backend": "cpu"} if api == "kdsl" else {"device": "cpu"}
        lib.launch(getattr(mod, name), dim, [*args, *outs], **kw)
        got[api] = [o.numpy() for o in outs]
    return got["kdsl"], got["warp"]


def _dtype(lib, t):
    """The dtype ``t`` (named by its kdsl class) in ``lib`` (kdsl or warp)."""
    names = {wp.int32: "int32", wp.uint32: "uint32", wp.vec2: "vec2", wp.vec3: "vec3",
             wp.vec4: "vec4"}  # fmt: skip
    return t if t is float else getattr(lib, names[t])


def _seeds(rng, n):
    a = rng.integers(-(2**31), 2**31 - 1, n, endpoint=True).astype(np.int32)
    a[:5] = [0, 1, -1, 2**31 - 1, -(2**31)]
    return a


def _ulps(a, b):
    """Distance in float32 units in the last place (ordered integer view)."""
    ia = a.astype(np.float32).view(np.int32).astype(np.int64)
    ib = b.astype(np.float32).view(np.int32).astype(np.int64)
    ia = np.where(ia < 0, -(2**31) - ia, ia)
    ib = np.where(ib < 0, -(2**31) - ib, ib)
    return np.abs(ia - ib)


def test_draws_match_warp(apis):
    rng = np.random.default_rng(5)
    n = 512
    lo = rng.integers(-100, 100, n).astype(np.int32)
    hi = (lo + rng.integers(1, 1000, n)).astype(np.int32)
    lam = rng.uniform(0.0, 12.0, n).astype(np.float32)
    lam[:3] = [0.0, 10.0, 0.5]
    cdf = (np.cumsum([1, 0, 3, 2, 0, 4]) / 10).astype(np.float32)
    kw_types = (wp.int32, wp.int32, wp.int32, wp.int32, float, float)
    ours, warps = _run_both(
        apis, "draws", n,
        list(zip([_seeds(rng, n), _seeds(rng, n), lo, hi, lam, cdf], kw_types)),
        [((n, 3), wp.int32), ((n, 7), wp.uint32), ((n, 8), float), ((n, 8), float)],
    )  # fmt: skip
    for k in range(3):  # integers, states and plain uniforms: bit for bit
        np.testing.assert_array_equal(ours[k], warps[k])
    # Through libm's cos/acos/log/pow: the same libm gives the same bits; allow 2 ulps.
    assert _ulps(ours[3], warps[3]).max() <= 2


@pytest.mark.parametrize("dim", [1, 2, 3, 4])
def test_noise_matches_warp(apis, dim):
    rng = np.random.default_rng(dim)
    n = 128
    x = rng.uniform(-20.0, 20.0, (n, dim)).astype(np.float32)
    x[:4] = np.array([0.0, 1.0, -3.0, 0.5])[:, None]  # lattice points and a cell centre
    vt = {1: float, 2: wp.vec2, 3: wp.vec3, 4: wp.vec4}[dim]
    ours, warps = _run_both(apis, f"noise{dim}", n,
                            [(_seeds(rng, n), wp.int32), (x[:, 0] if dim == 1 else x, vt)],
                            [((n, 2), float)])  # fmt: skip
    np.testing.assert_array_equal(ours[0], warps[0])


@pytest.mark.parametrize("dim", [2, 3, 4])
def test_curlnoise_matches_warp(apis, dim):
    rng = np.random.default_rng(10 + dim)
    n = 64
    x = rng.uniform(-8.0, 8.0, (n, dim)).astype(np.float32)
    vt = {2: wp.vec2, 3: wp.vec3, 4: wp.vec4}[dim]
    ours, warps = _run_both(apis, f"curl{dim}", n, [(_seeds(rng, n), wp.int32), (x, vt)],
                            [((n,), wp.vec2 if dim == 2 else wp.vec3)])  # fmt: skip
    np.testing.assert_array_equal(ours[0], warps[0])


@wp.kernel
def k_exits(seed: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.int32, ndim=2),
            final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    n = 0
    while wp.randi(state, 0, 4) != 0:  # a while loop that also breaks
        n += 1
        if n == 3:
            break
    out[i, 0] = n
    for k in wp.static(range(2)):  # unrolled: each copy advances state
        out[i, 1 + k] = wp.randi(state, 0, 100)
    final[i] = state


def test_inout_with_break_and_unrolled_loops():
    seed = np.arange(40, dtype=np.int32)
    out = wp.zeros((40, 3), dtype=wp.int32)
    final = wp.zeros(40, dtype=wp.uint32)
    wp.launch(k_exits, 40, [wp.from_numpy(seed), out, final], backend="interp")
    for i in range(40):
        s = R.Stream(R.rand_init(seed[i : i + 1]))
        n = 0
        while s.randi(np.int32(0), np.int32(4))[0] != 0:
            n += 1
            if n == 3:
                break
        want = [n, s.randi(np.int32(0), np.int32(100))[0], s.randi(np.int32(0), np.int32(100))[0]]
        np.testing.assert_array_equal(out.numpy()[i], want)
        assert final.numpy()[i] == s.state[0]


@wp.kernel
def k_noise_grad(x: wp.array(dtype=wp.vec2), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.noise(wp.rand_init(7), x[i])


def test_noise_gradient_is_the_analytic_one():
    xs = np.random.default_rng(3).uniform(-3.0, 3.0, (16, 2)).astype(np.float32)
    x = wp.array(xs, dtype=wp.vec2, requires_grad=True)
    out = wp.zeros(16, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(k_noise_grad, 16, [x, out], backend="cpu")
    tape.backward(grads={out: wp.array(np.ones(16, np.float32))})
    _, grad = R.perlin(R.rand_init(7), xs)
    np.testing.assert_allclose(x.grad.numpy(), grad, rtol=1e-4, atol=1e-5)
