"""``@kdsl.struct`` values: parameters, construction, fields, functions, arrays of structs.

Every kernel is built for float32 and float64 (struct fields of that type). Struct
parameters come in as one NumPy structured element; arrays of structs as NumPy
structured arrays in the struct's layout (``numpy_dtype()``), so a case proves
the backends read fields at NumPy's offsets. Outputs are plain float arrays.
"""

import numpy as np

import kdsl as wp
from kdsl.testing.case import Case, f64, uniform

N = 24


def _extremes(dtype) -> np.ndarray:
    """Values a struct field must carry through unchanged: zeros, infs, NaN, extremes."""
    fi = np.finfo(dtype)
    return np.array([0.0, -0.0, np.inf, -np.inf, np.nan, fi.max, -fi.max, fi.tiny,
                     fi.smallest_subnormal, -fi.smallest_subnormal, 1e-30, -1e30], dtype)  # fmt: skip


def _family(tname: str, F, np_f, req: tuple[str, ...]) -> list[Case]:
    V3 = wp.vector(3, F)
    M22 = wp.matrix((2, 2), F)

    @wp.struct
    class Inner:
        w: F
        k: wp.int16

    @wp.struct
    class Body:
        x: V3
        m: F
        n: wp.int32
        flag: wp.bool
        inner: Inner

    @wp.struct
    class Mixed:  # every alignment: 1, 2, 4 and 8 bytes, out of order
        a: wp.int8
        h: wp.float16
        b: wp.uint8
        f: F
        c: wp.uint16
        d: wp.float64
        e: wp.int8
        mat: M22

    @wp.kernel
    def param_fields(p: Body, a: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        out[i] = p.m * a[i] + p.x[i % 3] + F(p.n) + p.inner.w + F(p.inner.k)
        if p.flag:
            out[i] = -out[i]

    @wp.kernel
    def zero_construct(a: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        b = Body()
        out[i] = b.m + b.x[0] + b.x[1] + b.x[2] + F(b.n) + b.inner.w + a[i]

    @wp.kernel
    def keyword_construct(a: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        b = Body(m=a[i], x=V3(a[i], F(2.0), F(3.0)), inner=Inner(w=F(0.5), k=wp.int16(3)))
        out[i] = b.m * b.x[0] + b.x[2] + b.inner.w * F(b.inner.k) + F(b.n)

    @wp.kernel
    def positional_construct(a: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        b = Body(V3(a[i]), a[i] * F(2.0), i)
        out[i] = b.x[1] + b.m + F(b.n)

    @wp.kernel
    def field_assign(a: wp.array(dtype=F), b: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        s = Body()
        s.m = a[i]
        s.x.y = b[i]
        s.x = s.x * F(2.0)
        s.inner.w = s.m + s.x.y
        s.n += 3
        out[i] = s.inner.w + F(s.n) + s.x[1]

    @wp.func
    def moved(s: Body, dt: F) -> Body:
        r = s
        r.x = r.x + V3(dt, dt * F(2.0), dt * F(3.0))
        r.m = r.m * F(0.5)
        return r

    @wp.func
    def energy(s: Body) -> F:
        return F(0.5) * s.m * wp.dot(s.x, s.x)

    @wp.kernel
    def through_funcs(a: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        s = Body(m=a[i], x=V3(F(1.0), a[i], F(-1.0)))
        t = moved(s, a[i])
        # s is a value: moved() changed its own copy only.
        out[i] = energy(t) + s.m + s.x[0]

    @wp.kernel
    def branch_merge(a: wp.array(dtype=F), out: wp.array(dtype=F)):
        i = wp.tid()
        s = Body(m=a[i])
        if a[i] > F(0.0):
            s.m = s.m * F(2.0)
            s.inner.w = F(1.0)
        else:
            s.x = V3(F(1.0), F(2.0), F(3.0))
        out[i] = s.m + s.inner.w + s.x[2]

    @wp.kernel
    def loop_carried(a: wp.array(dtype=F), n: int, out: wp.array(dtype=F)):
        i = wp.tid()
        s = Body(m=a[i])
        for k in range(n):
            s.x = s.x + V3(s.m, F(1.0), F(k))
            s.m = s.m * F(0.5)
        j = 0
        while s.inner.w < F(3.0):
            s.inner.w += F(1.0)
            j += 1
        out[i] = s.x[0] + s.x[1] + s.x[2] + s.m + F(j)

    @wp.kernel
    def array_read(bodies: wp.array(dtype=Body), out: wp.array(dtype=F)):
        i = wp.tid()
        b = bodies[i]
        v = b.m * b.x[1] + F(b.n) + b.inner.w * F(b.inner.k)
        if b.flag:
            v = v + F(100.0)
        out[i] = v + bodies[i].x.z

    @wp.kernel
    def array_write_fields(bodies: wp.array(dtype=Body), a: wp.array(dtype=F),
                           out: wp.array(dtype=F)):  # fmt: skip
        i = wp.tid()
        bodies[i].m = a[i]
        bodies[i].x.y = a[i] * F(3.0)
        bodies[i].inner.w = F(2.0)
        bodies[i].n = i
        b = bodies[i]
        out[i] = b.m + b.x[0] + b.x[1] + b.x[2] + b.inner.w + F(b.n) + F(b.inner.k)

    @wp.kernel
    def array_whole_store(srcs: wp.array(dtype=Body), bodies: wp.array(dtype=Body),
                          a: wp.array(dtype=F), out: wp.array(dtype=F)):  # fmt: skip
        i = wp.tid()
        n = srcs.shape[0]
        s = srcs[(i + 1) % n]
        s.m = s.m + a[i]
        bodies[i] = s
        out[i] = bodies[i].m + bodies[i].x[0] + F(bodies[i].n)

    @wp.kernel
    def array_2d(bodies: wp.array2d(dtype=Body), out: wp.array2d(dtype=F)):
        i, j = wp.tid()
        out[i, j] = bodies[i, j].m * F(10.0) + bodies[i, j].x[j % 3] + bodies[i, j].inner.w

    @wp.kernel
    def mixed_layout(ms: wp.array(dtype=Mixed), out: wp.array(dtype=F)):
        i = wp.tid()
        m = ms[i]
        out[i] = (F(m.a) + F(m.h) + F(m.b) + m.f + F(m.c) + F(m.d) + F(m.e)
                  + m.mat[0, 1] + m.mat[1, 0])  # fmt: skip

    @wp.kernel
    def mixed_roundtrip(ms: wp.array(dtype=Mixed), out: wp.array(dtype=F)):
        i = wp.tid()
        m = ms[i]
        m.a = wp.int8(-i)
        m.h = wp.float16(1.5)
        m.c = wp.uint16(65535)
        m.d = wp.float64(i) * 0.25
        m.mat = M22(F(1.0), F(2.0), F(3.0), F(i))
        ms[i] = m
        r = ms[i]
        out[i] = F(r.a) + F(r.h) + F(r.b) + r.f + F(r.c) + F(r.d) + F(r.e) + r.mat[1, 1]

    @wp.kernel
    def extremes(bodies: wp.array(dtype=Body), out: wp.array(dtype=F), xs: wp.array(dtype=F)):
        i = wp.tid()
        b = bodies[i]
        c = Body(m=b.m, x=b.x)
        out[i] = c.m
        xs[i] = c.x[2]

    # --- inputs and references ------------------------------------------------------

    body_dt = Body.numpy_dtype()
    mixed_dt = Mixed.numpy_dtype()

    def bodies(rng, shape=N):
        b = np.zeros(shape, body_dt)
        b["x"] = uniform(rng, (*np.atleast_1d(shape), 3), -2.0, 2.0, np_f)
        b["m"] = uniform(rng, shape, 0.5, 3.0, np_f)
        b["n"] = rng.integers(-5, 5, shape)
        b["flag"] = rng.integers(0, 2, shape).astype(bool)
        b["inner"]["w"] = uniform(rng, shape, -1.0, 1.0, np_f)
        b["inner"]["k"] = rng.integers(-300, 300, shape)
        return b

    def mixed(rng):
        m = np.zeros(N, mixed_dt)
        m["a"] = rng.integers(-128, 128, N)
        m["h"] = uniform(rng, N, -4.0, 4.0, np.float16)
        m["b"] = rng.integers(0, 256, N)
        m["f"] = uniform(rng, N, -4.0, 4.0, np_f)
        m["c"] = rng.integers(0, 65536, N)
        m["d"] = uniform(rng, N, -1e3, 1e3, np.float64)
        m["e"] = rng.integers(-128, 128, N)
        m["mat"] = uniform(rng, (N, 2, 2), -2.0, 2.0, np_f)
        return m

    def xs(rng, lo=-2.0, hi=2.0):
        a = uniform(rng, N, lo, hi, np_f)
        a[:2] = [0.0, -0.0]
        return a

    zeros = np.zeros(N, np_f)

    def ref_param(ins):
        p, a = ins["p"], f64(ins["a"])
        i = np.arange(N)
        v = (f64(p["m"]) * a + f64(p["x"])[i % 3] + f64(p["n"]) + f64(p["inner"]["w"])
             + f64(p["inner"]["k"]))  # fmt: skip
        return {"out": -v if p["flag"] else v}

    def ref_keyword(ins):
        a = f64(ins["a"])
        return {"out": a * a + 3.0 + 1.5}

    def ref_positional(ins):
        a = f64(ins["a"])
        return {"out": a + 2.0 * a + np.arange(N)}

    def ref_assign(ins):
        a, b = f64(ins["a"]), f64(ins["b"])
        w = a + 2.0 * b
        return {"out": w + 3.0 + 2.0 * b}

    def ref_funcs(ins):
        a = f64(ins["a"])
        x = np.stack([1.0 + a, a + 2.0 * a, -1.0 + 3.0 * a], axis=1)
        m = a * 0.5
        return {"out": 0.5 * m * np.sum(x * x, axis=1) + a + 1.0}

    def ref_branch(ins):
        a = f64(ins["a"])
        pos = a > 0
        return {"out": np.where(pos, 2.0 * a + 1.0, a + 3.0)}

    def ref_loop(ins):
        a, n = f64(ins["a"]), ins["n"]
        x, m = np.zeros((N, 3)), a.copy()
        for k in range(n):
            x += np.stack([m, np.ones(N), np.full(N, float(k))], axis=1)
            m *= 0.5
        return {"out": x.sum(axis=1) + m + 3.0}

    def ref_array_read(ins):
        b = ins["bodies"]
        v = (f64(b["m"]) * f64(b["x"][:, 1]) + f64(b["n"])
             + f64(b["inner"]["w"]) * f64(b["inner"]["k"]))  # fmt: skip
        return {"out": v + np.where(b["flag"], 100.0, 0.0) + f64(b["x"][:, 2])}

    def ref_write_fields(ins):
        b, a = ins["bodies"], f64(ins["a"])
        x = f64(b["x"])
        return {"out": a + x[:, 0] + 3.0 * a + x[:, 2] + 2.0 + np.arange(N)
                + f64(b["inner"]["k"])}  # fmt: skip

    def ref_2d(ins):
        b = ins["bodies"]
        xj = np.array([[b["x"][i, j, j % 3] for j in range(b.shape[1])]
                       for i in range(b.shape[0])])  # fmt: skip
        return {"out": f64(b["m"]) * 10.0 + f64(xj) + f64(b["inner"]["w"])}

    def ref_mixed(ins):
        m = ins["ms"]
        v = (f64(m["a"]) + f64(m["h"]) + f64(m["b"]) + f64(m["f"]) + f64(m["c"]) + f64(m["d"])
             + f64(m["e"]) + f64(m["mat"][:, 0, 1]) + f64(m["mat"][:, 1, 0]))  # fmt: skip
        return {"out": v}

    def ref_mixed_roundtrip(ins):
        m, i = ins["ms"], np.arange(N)
        d = f64((i * 0.25).astype(np.float64))
        return {"out": -i + 1.5 + f64(m["b"]) + f64(m["f"]) + 65535.0 + d + f64(m["e"]) + i}

    def ref_extremes(ins):
        b = ins["bodies"]
        return {"out": f64(b["m"]), "xs": f64(b["x"][:, 2])}

    def extreme_bodies(rng):
        b = np.zeros(12, body_dt)
        e = _extremes(np_f)
        b["m"] = e
        b["x"][:, 2] = e[::-1]
        return b

    def ref_whole_store(ins):
        b, a = ins["srcs"], f64(ins["a"])
        nxt = np.roll(np.arange(N), -1)
        m = f64(b["m"]).astype(np_f).astype(np.float64)[nxt] + a
        return {"out": f64(m.astype(np_f)) + f64(b["x"][:, 0])[nxt] + f64(b["n"])[nxt]}

    def one_body(rng):
        return bodies(rng, ())

    cases = [
        Case("param_fields", param_fields, N,
             lambda rng: {"p": one_body(rng), "a": xs(rng), "out": zeros.copy()},
             ref_param, ("out",)),
        Case("param_fields_flag", param_fields, N,
             lambda rng: {"p": _flagged(one_body(rng)), "a": xs(rng), "out": zeros.copy()},
             ref_param, ("out",)),
        Case("zero_construct", zero_construct, N,
             lambda rng: {"a": xs(rng), "out": zeros.copy()},
             lambda ins: {"out": f64(ins["a"])}, ("out",)),
        Case("keyword_construct", keyword_construct, N,
             lambda rng: {"a": xs(rng), "out": zeros.copy()}, ref_keyword, ("out",)),
        Case("positional_construct", positional_construct, N,
             lambda rng: {"a": xs(rng), "out": zeros.copy()}, ref_positional, ("out",)),
        Case("field_assign", field_assign, N,
             lambda rng: {"a": xs(rng), "b": xs(rng), "out": zeros.copy()}, ref_assign,
             ("out",)),
        Case("through_funcs", through_funcs, N,
             lambda rng: {"a": xs(rng), "out": zeros.copy()}, ref_funcs, ("out",)),
        Case("branch_merge", branch_merge, N,
             lambda rng: {"a": xs(rng), "out": zeros.copy()}, ref_branch, ("out",)),
        Case("loop_carried", loop_carried, N,
             lambda rng: {"a": xs(rng), "n": 5, "out": zeros.copy()}, ref_loop, ("out",)),
        Case("array_read", array_read, N,
             lambda rng: {"bodies": bodies(rng), "out": zeros.copy()}, ref_array_read, ("out",)),
        Case("array_write_fields", array_write_fields, N,
             lambda rng: {"bodies": bodies(rng), "a": xs(rng), "out": zeros.copy()},
             ref_write_fields, ("out",)),
        Case("array_2d", array_2d, (4, 5),
             lambda rng: {"bodies": bodies(rng, (4, 5)), "out": np.zeros((4, 5), np_f)},
             ref_2d, ("out",)),
        Case("mixed_layout", mixed_layout, N,
             lambda rng: {"ms": mixed(rng), "out": zeros.copy()}, ref_mixed, ("out",),
             tol=(1e-5, 1e-4) if np_f == np.float32 else None),
        Case("mixed_roundtrip", mixed_roundtrip, N,
             lambda rng: {"ms": mixed(rng), "out": zeros.copy()}, ref_mixed_roundtrip,
             ("out",), tol=(1e-5, 1e-4) if np_f == np.float32 else None),
        Case("extremes", extremes, 12,
             lambda rng: {"bodies": extreme_bodies(rng), "out": np.zeros(12, np_f),
                          "xs": np.zeros(12, np_f)}, ref_extremes, ("out", "xs"),
             tol=(0.0, 0.0)),
        Case("array_whole_store", array_whole_store, N,
             lambda rng: {"srcs": bodies(rng), "bodies": np.zeros(N, body_dt), "a": xs(rng),
                          "out": zeros.copy()}, ref_whole_store, ("out",)),
    ]  # fmt: skip
    out = []
    for c in cases:
        # Mixed holds a float64 field whatever F is.
        uses_f64 = c.kernel in (mixed_layout, mixed_roundtrip)
        needs = ("fp64",) if req or uses_f64 else ()
        out.append(Case(f"struct_{c.name}_{tname}", c.kernel, c.dim, c.make_inputs, c.reference,
                        c.outputs, requires=needs, tol=c.tol))  # fmt: skip
    return out


def _flagged(p: np.ndarray) -> np.ndarray:
    p = p.copy()
    p["flag"] = True
    return p


CASES: list[Case] = [
    *_family("f32", wp.float32, np.float32, ()),
    *_family("f64", wp.float64, np.float64, ("fp64",)),
]
