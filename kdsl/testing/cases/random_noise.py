"""Random numbers and noise: Warp's PCG streams, samplers, Perlin and curl noise.

References come from ``kdsl.testing.random_ref``, a NumPy model of the same
generator, so the suite needs no Warp. Integer draws and ``randf`` compare
exactly; samplers that go through ``cos``/``acos``/``log`` compare at float32
tolerance. Every sampler case also checks the final state, i.e. how many draws
the call consumed. Seeds and offsets include 0, +-1 and the int32 extremes.
"""

import numpy as np

import kdsl as wp
from kdsl.testing import random_ref as R
from kdsl.testing.case import Case

N = 32
I32_MIN, I32_MAX = -(2**31), 2**31 - 1
#: Curl and 4-D noise run per thread on ``interp``: keep them small.
N_SMALL = 8


def _ints(rng, n=N):
    """int32 seeds/offsets: the edge values first, then uniform over the whole range."""
    a = rng.integers(I32_MIN, I32_MAX, size=n, endpoint=True).astype(np.int32)
    a[:5] = [0, 1, -1, I32_MAX, I32_MIN]
    return a


def _seeded(rng, **extra):
    return {"seed": _ints(rng), "offset": _ints(rng)[::-1].copy(), **extra}


def _stream(inp):
    return R.Stream(R.rand_init(inp["seed"], inp["offset"]))


# --- seeding and integer/uniform draws ------------------------------------------------


@wp.kernel
def rand_init_seed(seed: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.uint32)):
    i = wp.tid()
    out[i] = wp.rand_init(seed[i])


@wp.kernel
def rand_init_offset(seed: wp.array(dtype=wp.int32), offset: wp.array(dtype=wp.int32),
                     out: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    out[i] = wp.rand_init(seed[i], offset[i])


def _stream_kernel(draw, dtype):
    """A kernel storing four draws of ``draw(state)`` per thread."""

    @wp.kernel
    def stream(seed: wp.array(dtype=wp.int32), offset: wp.array(dtype=wp.int32),
               out: wp.array(dtype=dtype, ndim=2)):  # fmt: skip
        i = wp.tid()
        state = wp.rand_init(seed[i], offset[i])
        for k in range(4):
            out[i, k] = draw(state)

    return stream


def _range_kernel(draw, dtype):
    """A kernel storing two draws of ``draw(state, lo, hi)`` per thread."""

    @wp.kernel
    def in_range(seed: wp.array(dtype=wp.int32), offset: wp.array(dtype=wp.int32),
                 lo: wp.array(dtype=dtype), hi: wp.array(dtype=dtype),
                 out: wp.array(dtype=dtype, ndim=2)):  # fmt: skip
        i = wp.tid()
        state = wp.rand_init(seed[i], offset[i])
        out[i, 0] = draw(state, lo[i], hi[i])
        out[i, 1] = draw(state, lo[i], hi[i])

    return in_range


def _draws(method, k=4, dtype=None):
    def ref(inp):
        s = _stream(inp)
        out = np.stack([getattr(s, method)() for _ in range(k)], axis=-1)
        return {"out": out if dtype is None else out.astype(dtype)}

    return ref


def _int_ranges(rng, dtype):
    if dtype == np.int32:
        lo = rng.integers(-1000, 1000, N).astype(np.int32)
        hi = (lo + rng.integers(1, 500, N)).astype(np.int32)
        edges = [(0, 1), (-5, 5), (I32_MIN, I32_MAX), (7, 7), (10, -10), (I32_MIN, 0),
                 (-1, I32_MAX)]  # fmt: skip
    else:
        lo = rng.integers(0, 2**31, N).astype(np.uint32)
        hi = (lo + rng.integers(1, 10**6, N)).astype(np.uint32)
        edges = [(0, 1), (0, 2**32 - 1), (2**32 - 2, 2**32 - 1), (9, 9), (10, 3), (0, 2**31)]
    for k, (a, b) in enumerate(edges):
        lo[k], hi[k] = a, b
    return lo, hi


def _range_ref(method):
    def ref(inp):
        s = _stream(inp)
        out = np.stack([getattr(s, method)(inp["lo"], inp["hi"]) for _ in range(2)], axis=-1)
        return {"out": out}

    return ref


def _float_ranges(rng):
    lo = rng.uniform(-10, 10, N).astype(np.float32)
    hi = (lo + rng.uniform(0, 10, N)).astype(np.float32)
    edges = [(0.0, 1.0), (-1e30, 1e30), (5.0, 5.0), (3.0, -3.0), (-0.0, 0.0),
             (1e-45, 1e-44), (-np.inf, np.inf), (0.0, np.inf), (-1e-30, 1e-30)]  # fmt: skip
    for k, (a, b) in enumerate(edges):
        lo[k], hi[k] = a, b
    return lo, hi


def _seeding_cases():
    return [
        Case("rand_init_seed", rand_init_seed, N,
             lambda rng: {"seed": _ints(rng), "out": np.zeros(N, np.uint32)},
             lambda inp: {"out": R.rand_init(inp["seed"])}, ("out",)),
        Case("rand_init_offset", rand_init_offset, N,
             lambda rng: _seeded(rng, out=np.zeros(N, np.uint32)),
             lambda inp: {"out": R.rand_init(inp["seed"], inp["offset"])}, ("out",)),
        Case("randi_stream", _stream_kernel(wp.randi, wp.int32), N,
             lambda rng: _seeded(rng, out=np.zeros((N, 4), np.int32)), _draws("randi"), ("out",)),
        Case("randi_range", _range_kernel(wp.randi, wp.int32), N,
             lambda rng: _seeded(rng, **dict(zip(("lo", "hi"), _int_ranges(rng, np.int32))),
                                 out=np.zeros((N, 2), np.int32)),
             _range_ref("randi"), ("out",)),
        Case("randu_stream", _stream_kernel(wp.randu, wp.uint32), N,
             lambda rng: _seeded(rng, out=np.zeros((N, 4), np.uint32)), _draws("randu"), ("out",)),
        Case("randu_range", _range_kernel(wp.randu, wp.uint32), N,
             lambda rng: _seeded(rng, **dict(zip(("lo", "hi"), _int_ranges(rng, np.uint32))),
                                 out=np.zeros((N, 2), np.uint32)),
             _range_ref("randu"), ("out",)),
        Case("randf_stream", _stream_kernel(wp.randf, float), N,
             lambda rng: _seeded(rng, out=np.zeros((N, 4), np.float32)), _draws("randf"),
             ("out",), tol=(0.0, 0.0)),
        Case("randf_range", _range_kernel(wp.randf, float), N,
             lambda rng: _seeded(rng, **dict(zip(("lo", "hi"), _float_ranges(rng))),
                                 out=np.zeros((N, 2), np.float32)),
             _range_ref("randf"), ("out",), tol=(0.0, 0.0)),
        Case("randn_stream", _stream_kernel(wp.randn, float), N,
             lambda rng: _seeded(rng, out=np.zeros((N, 4), np.float32)), _draws("randn"),
             ("out",), tol=(1e-5, 1e-6)),
    ]  # fmt: skip


# --- samplers -------------------------------------------------------------------------


def _sampler_kernel(sampler, vtype):
    """A kernel drawing two samples per thread and storing the final state."""

    @wp.kernel
    def sample(seed: wp.array(dtype=wp.int32), offset: wp.array(dtype=wp.int32),
               out: wp.array(dtype=vtype, ndim=2), final: wp.array(dtype=wp.uint32)):  # fmt: skip
        i = wp.tid()
        state = wp.rand_init(seed[i], offset[i])
        out[i, 0] = sampler(state)
        out[i, 1] = sampler(state)
        final[i] = state

    return sample


_SAMPLERS = {
    "sample_triangle": (wp.sample_triangle, wp.vec2, lambda s: s.sample_triangle()),
    "sample_unit_ring": (wp.sample_unit_ring, wp.vec2, lambda s: s.sample_unit_ring()),
    "sample_unit_disk": (wp.sample_unit_disk, wp.vec2, lambda s: s.sample_unit_disk()),
    "sample_unit_sphere_surface": (wp.sample_unit_sphere_surface, wp.vec3,
                                   lambda s: s.sample_unit_sphere_surface()),
    "sample_unit_sphere": (wp.sample_unit_sphere, wp.vec3, lambda s: s.sample_unit_sphere()),
    "sample_unit_hemisphere_surface": (wp.sample_unit_hemisphere_surface, wp.vec3,
                                       lambda s: s.sample_unit_hemisphere_surface()),
    "sample_unit_hemisphere": (wp.sample_unit_hemisphere, wp.vec3,
                               lambda s: s.sample_unit_hemisphere()),
    "sample_unit_square": (wp.sample_unit_square, wp.vec2, lambda s: s.sample_unit_box(2)),
    "sample_unit_cube": (wp.sample_unit_cube, wp.vec3, lambda s: s.sample_unit_box(3)),
}  # fmt: skip


def _sampler_cases():
    out = []
    for name, (sampler, vtype, draw) in _SAMPLERS.items():
        n = vtype.__kdsl_type__.length

        def make(rng, n=n):
            return _seeded(rng, out=np.zeros((N, 2, n), np.float32),
                           final=np.zeros(N, np.uint32))  # fmt: skip

        def ref(inp, draw=draw):
            s = _stream(inp)
            samples = np.stack([draw(s), draw(s)], axis=1)
            return {"out": samples, "final": s.state}

        out.append(Case(name, _sampler_kernel(sampler, vtype), N, make, ref, ("out", "final"),
                        tol=(1e-5, 1e-6)))  # fmt: skip
    return out


@wp.kernel
def sample_cdf_kernel(seed: wp.array(dtype=wp.int32), offset: wp.array(dtype=wp.int32),
                      cdf: wp.array(dtype=float), out: wp.array(dtype=wp.int32, ndim=2),
                      final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i], offset[i])
    for k in range(3):
        out[i, k] = wp.sample_cdf(state, cdf)
    final[i] = state


def _cdf_case(name, weights):
    def make(rng):
        w = np.asarray(weights, np.float64)
        cdf = (np.cumsum(w) / w.sum()).astype(np.float32) if len(w) else np.zeros(0, np.float32)
        return _seeded(rng, cdf=cdf, out=np.zeros((N, 3), np.int32), final=np.zeros(N, np.uint32))

    def ref(inp):
        s = _stream(inp)
        out = np.stack([s.sample_cdf(inp["cdf"]) for _ in range(3)], axis=-1)
        return {"out": out, "final": s.state}

    return Case(name, sample_cdf_kernel, N, make, ref, ("out", "final"))


@wp.kernel
def poisson_kernel(seed: wp.array(dtype=wp.int32), offset: wp.array(dtype=wp.int32),
                   lam: wp.array(dtype=float), out: wp.array(dtype=wp.uint32, ndim=2),
                   final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i], offset[i])
    out[i, 0] = wp.poisson(state, lam[i])
    out[i, 1] = wp.poisson(state, lam[i])
    final[i] = state


def _poisson_case(name, lo, hi, edges):
    def make(rng):
        lam = rng.uniform(lo, hi, N).astype(np.float32)
        lam[: len(edges)] = edges
        return _seeded(rng, lam=lam, out=np.zeros((N, 2), np.uint32), final=np.zeros(N, np.uint32))

    def ref(inp):
        s = _stream(inp)
        out = np.stack([s.poisson(inp["lam"]), s.poisson(inp["lam"])], axis=-1)
        return {"out": out, "final": s.state}

    return Case(name, poisson_kernel, N, make, ref, ("out", "final"))


# --- the state as an in-out variable: loops, branches, conditions, functions -----------


@wp.kernel
def stream_loop(seed: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32),
                out: wp.array(dtype=float), final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    total = 0.0
    for _k in range(count[i]):
        total += wp.randf(state)
    out[i] = total
    final[i] = state


@wp.kernel
def stream_branch(seed: wp.array(dtype=wp.int32), p: wp.array(dtype=float),
                  out: wp.array(dtype=float), final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    v = 0.0
    if wp.randf(state) < p[i]:
        v = wp.randf(state, 10.0, 20.0)
    else:
        v = float(wp.randi(state, -3, 3))
    out[i] = v
    final[i] = state


@wp.kernel
def stream_while(seed: wp.array(dtype=wp.int32), p: wp.array(dtype=float),
                 out: wp.array(dtype=wp.int32), final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    n = 0
    while wp.randf(state) < p[i]:
        n += 1
    out[i] = n
    final[i] = state


@wp.kernel
def stream_short_circuit(seed: wp.array(dtype=wp.int32), p: wp.array(dtype=float),
                         out: wp.array(dtype=float), final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    # The right operand of `and` and the chosen arm of the ternary draw only when run.
    hit = p[i] > 0.5 and wp.randf(state) < 0.5
    v = wp.randf(state) if hit else wp.randf(state, -2.0, -1.0) - wp.randf(state)
    out[i] = v
    final[i] = state


@wp.func
def draw_pair(state: wp.inout(wp.uint32)) -> float:
    a = wp.randf(state)
    return a + 10.0 * wp.randf(state)


@wp.func
def peek(state: wp.uint32) -> float:
    # A by-value parameter: the caller's state is not advanced (as in Warp).
    return wp.randf(state)


@wp.kernel
def stream_funcs(seed: wp.array(dtype=wp.int32), states: wp.array(dtype=wp.uint32),
                 out: wp.array(dtype=float, ndim=2), final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    out[i, 0] = peek(state)
    out[i, 1] = draw_pair(state)
    out[i, 2] = peek(state)
    # An array element is a temporary: it is read, never written back.
    out[i, 3] = wp.randf(states[i]) - wp.randf(states[i])
    final[i] = state


@wp.kernel
def stream_nested(seed: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.uint32),
                  final: wp.array(dtype=wp.uint32)):  # fmt: skip
    i = wp.tid()
    state = wp.rand_init(seed[i])
    hits = wp.uint32(0)
    for a in range(3):
        for _b in range(a + 1):
            if wp.randu(state) % wp.uint32(3) == wp.uint32(0):
                hits += wp.randu(state, wp.uint32(1), wp.uint32(5))
    out[i] = hits
    final[i] = state


def _nested_ref(inp):
    outs, finals = [], []
    for seed in inp["seed"]:
        s = R.Stream(R.rand_init(np.array([seed])))
        hits = 0
        for a in range(3):
            for _ in range(a + 1):
                if s.randu()[0] % 3 == 0:
                    hits += int(s.randu(1, 5)[0])
        outs.append(hits)
        finals.append(s.state[0])
    return {"out": np.array(outs, np.uint32), "final": np.array(finals, np.uint32)}


def _stream_cases():
    def loop_make(rng):
        count = rng.integers(0, 12, N).astype(np.int32)
        return {"seed": _ints(rng), "count": count, "out": np.zeros(N, np.float32),
                "final": np.zeros(N, np.uint32)}  # fmt: skip

    def loop_ref(inp):
        s = R.Stream(R.rand_init(inp["seed"]))
        total = np.zeros(N, np.float32)
        final = s.state.copy()
        for k in range(int(inp["count"].max())):
            u = s.randf()
            live = k < inp["count"]
            total = np.where(live, (total + u).astype(np.float32), total)
            final = np.where(live, s.state, final)
        return {"out": total, "final": final}

    def p_make(rng, out_dtype=np.float32):
        p = rng.uniform(0, 1, N).astype(np.float32)
        p[:4] = [0.0, 0.95, 0.5, 0.9]
        return {"seed": _ints(rng), "p": p, "out": np.zeros(N, out_dtype),
                "final": np.zeros(N, np.uint32)}  # fmt: skip

    def per_thread(fn):
        """A reference that runs ``fn(stream, inputs, i)`` for each thread on its own stream."""

        def ref(inp):
            outs, finals = [], []
            for i in range(N):
                s = R.Stream(R.rand_init(inp["seed"][i : i + 1]))
                outs.append(fn(s, inp, i))
                finals.append(s.state[0])
            return {"out": np.array(outs), "final": np.array(finals, np.uint32)}

        return ref

    def branch(s, inp, i):
        if s.randf()[0] < inp["p"][i]:
            return s.randf(10.0, 20.0)[0]
        return float(s.randi(np.int32(-3), np.int32(3))[0])

    def while_(s, inp, i):
        n = 0
        while s.randf()[0] < inp["p"][i]:
            n += 1
        return n

    def short(s, inp, i):
        hit = inp["p"][i] > 0.5 and s.randf()[0] < 0.5
        if hit:
            return s.randf()[0]
        a = s.randf(-2.0, -1.0)[0]
        return np.float32(a - s.randf()[0])

    def funcs_make(rng):
        return {"seed": _ints(rng), "states": R.rand_init(_ints(rng)),
                "out": np.zeros((N, 4), np.float32), "final": np.zeros(N, np.uint32)}  # fmt: skip

    def funcs_ref(inp):
        s = R.Stream(R.rand_init(inp["seed"]))
        peek0 = R.Stream(s.state).randf()
        a = s.randf()
        b = s.randf()
        peek1 = R.Stream(s.state).randf()
        pair = (a + np.float32(10.0) * b).astype(np.float32)
        zero = np.zeros(N, np.float32)
        return {"out": np.stack([peek0, pair, peek1, zero], axis=-1), "final": s.state}

    return [
        Case("random_stream_loop", stream_loop, N, loop_make, loop_ref, ("out", "final")),
        Case("random_stream_branch", stream_branch, N, p_make, per_thread(branch),
             ("out", "final")),
        Case("random_stream_while", stream_while, N, lambda rng: p_make(rng, np.int32),
             per_thread(while_), ("out", "final")),
        Case("random_stream_short_circuit", stream_short_circuit, N, p_make, per_thread(short),
             ("out", "final")),
        Case("random_stream_funcs", stream_funcs, N, funcs_make, funcs_ref, ("out", "final")),
        Case("random_stream_nested_loops", stream_nested, N,
             lambda rng: {"seed": _ints(rng), "out": np.zeros(N, np.uint32),
                          "final": np.zeros(N, np.uint32)},
             _nested_ref, ("out", "final")),
    ]  # fmt: skip


# --- noise ----------------------------------------------------------------------------

_VEC = {1: float, 2: wp.vec2, 3: wp.vec3, 4: wp.vec4}


def _points(rng, n, dim):
    """Points over several cells: negatives, exact integers (offset 0), -0.0, large values."""
    p = rng.uniform(-6.0, 6.0, (n, dim)).astype(np.float32)
    p[0] = 0.0
    p[1] = -0.0
    p[2] = 3.0
    p[3] = -2.0
    p[4] = 1000.25
    p[5] = -1e-7
    p[6] = 0.5
    return p if dim > 1 else p[:, 0].copy()


def _noise_kernel(vtype):
    @wp.kernel
    def noise_kernel(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=vtype),
                     out: wp.array(dtype=float)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.noise(wp.rand_init(seed[i]), x[i])

    return noise_kernel


def _pnoise_kernel(dim):
    vtype = _VEC[dim]

    @wp.kernel
    def pnoise_kernel(seed: wp.array(dtype=wp.int32), x: wp.array(dtype=vtype),
                      period: wp.array(dtype=wp.vec4i), out: wp.array(dtype=float)):  # fmt: skip
        i = wp.tid()
        q = period[i]
        state = wp.rand_init(seed[i])
        # One period per axis of the point.
        if wp.static(dim == 1):
            out[i] = wp.pnoise(state, x[i], q[0])
        elif wp.static(dim == 2):
            out[i] = wp.pnoise(state, x[i], q[0], q[1])
        elif wp.static(dim == 3):
            out[i] = wp.pnoise(state, x[i], q[0], q[1], q[2])
        else:
            out[i] = wp.pnoise(state, x[i], q[0], q[1], q[2], q[3])

    return pnoise_kernel


def _noise_cases():
    out = []
    for dim in (1, 2, 3, 4):
        n = N if dim < 4 else N_SMALL

        def make(rng, n=n, dim=dim):
            seeds = _ints(rng, n)
            return {"seed": seeds, "x": _points(rng, n, dim), "out": np.zeros(n, np.float32)}

        def ref(inp, dim=dim):
            p = inp["x"].reshape(len(inp["x"]), dim)
            return {"out": R.perlin(R.rand_init(inp["seed"]), p)[0]}

        out.append(Case(f"noise_{dim}d", _noise_kernel(_VEC[dim]), n, make, ref, ("out",)))

        def pmake(rng, n=n, dim=dim):
            period = rng.integers(1, 9, (n, 4)).astype(np.int32)
            period[0] = 1
            period[1] = 1000
            x = np.abs(_points(rng, n, dim))  # Warp defines periodic noise for x >= 0
            return {"seed": _ints(rng, n), "x": x, "period": period,
                    "out": np.zeros(n, np.float32)}  # fmt: skip

        def pref(inp, dim=dim):
            p = inp["x"].reshape(len(inp["x"]), dim)
            value = R.perlin(R.rand_init(inp["seed"]), p, period=inp["period"][:, :dim].T)[0]
            return {"out": value}

        out.append(Case(f"pnoise_{dim}d", _pnoise_kernel(dim), n, pmake, pref, ("out",)))
    return out


def _curl_kernel(vtype, ctype):
    """A kernel storing ``curlnoise`` of points of type ``vtype`` (curls of type ``ctype``)."""

    @wp.kernel
    def curl(seed: wp.int32, x: wp.array(dtype=vtype), octaves: wp.uint32, lacunarity: float,
             gain: float, out: wp.array(dtype=ctype)):  # fmt: skip
        i = wp.tid()
        out[i] = wp.curlnoise(wp.rand_init(seed), x[i], octaves, lacunarity, gain)

    return curl


@wp.kernel
def curl2_defaults(seed: wp.int32, x: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    # Warp's default arguments (octaves=1, lacunarity=2, gain=0.5) are overloads here.
    out[i] = wp.curlnoise(wp.rand_init(seed), x[i]) + wp.curlnoise(wp.rand_init(seed), x[i], 2)


def _curl_cases():
    out = []
    for dim, ctype, octaves, lac, gain in ((2, wp.vec2, 3, 2.0, 0.5), (3, wp.vec3, 2, 1.7, 0.6),
                                           (4, wp.vec3, 1, 2.0, 0.5)):  # fmt: skip
        n = N_SMALL

        def make(rng, n=n, dim=dim, octaves=octaves, lac=lac, gain=gain):
            return {"seed": -12345, "x": _points(rng, n, dim), "octaves": octaves,
                    "lacunarity": lac, "gain": gain,
                    "out": np.zeros((n, 3 if dim > 2 else 2), np.float32)}  # fmt: skip

        def ref(inp):
            st = R.rand_init(inp["seed"])
            return {"out": R.curlnoise(st, inp["x"], int(inp["octaves"]), inp["lacunarity"],
                                       inp["gain"])}  # fmt: skip

        kern = _curl_kernel(_VEC[dim], ctype)
        out.append(Case(f"curlnoise_{dim}d", kern, n, make, ref, ("out",), tol=(1e-5, 1e-5)))

    def dmake(rng):
        return {"seed": 99, "x": _points(rng, N_SMALL, 2), "out": np.zeros((N_SMALL, 2),
                                                                        np.float32)}  # fmt: skip

    def dref(inp):
        st = R.rand_init(inp["seed"])
        one = R.curlnoise(st, inp["x"], 1, 2.0, 0.5)
        two = R.curlnoise(st, inp["x"], 2, 2.0, 0.5)
        return {"out": one + two}

    out.append(Case("curlnoise_defaults", curl2_defaults, N_SMALL, dmake, dref, ("out",),
                    tol=(1e-5, 1e-5)))  # fmt: skip
    return out


CASES: list[Case] = [
    *_seeding_cases(),
    *_sampler_cases(),
    _cdf_case("sample_cdf", [0.1, 0.0, 0.4, 0.0, 0.0, 0.3, 0.2]),
    _cdf_case("sample_cdf_single_bin", [1.0]),
    _cdf_case("sample_cdf_empty", []),
    _poisson_case("poisson_small", 0.0, 10.0, [0.0, 0.5, 1.0, 9.99, -1.0, 1e-6, np.nan]),
    _poisson_case("poisson_large", 10.0, 500.0, [10.0, 10.5, 1000.0, 1e5]),
    *_stream_cases(),
    *_noise_cases(),
    *_curl_cases(),
]
