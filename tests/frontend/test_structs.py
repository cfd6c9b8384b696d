"""``@kdsl.struct``: Python-side instances, kernel use, arrays of structs and their layout."""

import re

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslLaunchError, KdslTypeError


@wp.struct
class Inner:
    y: float
    k: wp.int8


@wp.struct
class Particle:
    x: wp.vec3
    m: float
    ids: wp.array(dtype=int)
    inner: Inner


@wp.struct
class Rec:  # fields of every alignment, out of order
    a: wp.int8
    h: wp.float16
    d: wp.float64
    on: wp.bool
    v: wp.vec3
    inner: Inner
    m: wp.mat22d
    u: wp.uint16


BACKENDS = ["interp", "cpu"]


def _line(marker: str) -> int:
    with open(__file__) as f:
        return next(n for n, text in enumerate(f, 1) if marker in text)


# --- Python side -----------------------------------------------------------------------


def test_instances_zero_fill_and_convert():
    p = Particle()
    assert p.m == 0 and p.m.dtype == np.float32 and p.ids is None
    assert isinstance(p.x, wp.vec3) and isinstance(p.inner, Inner)
    p.m = 2  # an int for a float field is fine (as for launch arguments)
    p.x = (1, 2, 3)
    assert p.m.dtype == np.float32 and isinstance(p.x, wp.vec3) and p.x[2] == 3
    q = Particle(m=2.0, x=wp.vec3(1, 2, 3))
    assert q == p and "m=" in repr(q)
    with pytest.raises(KdslTypeError, match="holds arrays"):
        Particle.numpy_dtype()
    with pytest.raises(KdslTypeError, match="holding arrays"):
        Particle().numpy_value()


def test_instance_errors():
    p = Particle()
    with pytest.raises(KdslTypeError, match=r"no field 'q'.*x, m, ids, inner"):
        p.q = 1
    with pytest.raises(KdslTypeError, match=r"field 'x' of struct Particle.*single number"):
        p.x = 3.0
    with pytest.raises(KdslTypeError, match="field 'inner' of struct Particle holds a Inner"):
        p.inner = 1
    with pytest.raises(KdslTypeError, match="1-d array of i32"):
        p.ids = wp.zeros(3, dtype=float)
    with pytest.raises(KdslTypeError, match=r"field 'k'.*does not fit"):
        p.inner.k = 300


def test_unsupported_field_type_is_located():
    with pytest.raises(KdslTypeError) as e:

        @wp.struct
        class Bad:
            a: float
            name: str  # BAD-FIELD

    assert "field 'name' of struct Bad has type str" in str(e.value)
    assert e.value.loc.line == _line("# BAD-FIELD")


def test_nested_struct_layout_matches_c():
    dt = Rec.numpy_dtype()
    # C layout: a@0, h@2, d@8, on@16, v@20, inner@32 (f32 + i8 -> 8 bytes), m@40, u@72; size 80.
    assert [dt.fields[n][1] for n in dt.names] == [0, 2, 8, 16, 20, 32, 40, 72]
    assert dt.itemsize == 80 and dt.alignment == 8


# --- kernels ---------------------------------------------------------------------------


@wp.func
def heavier(p: Particle, dm: float) -> Particle:
    q = p
    q.m = q.m + dm
    q.inner.y = 7.0
    return q


@wp.kernel
def use_particle(p: Particle, out: wp.array(dtype=float)):
    i = wp.tid()
    q = heavier(p, float(i))
    z = Particle(m=2.0, ids=p.ids)
    z.x = wp.vec3(1.0, 2.0, 3.0)
    out[i] = q.m + q.x[1] + float(q.ids[i]) + q.inner.y + z.m + z.x.z + float(q.inner.k) + p.m


@pytest.mark.parametrize("backend", BACKENDS)
def test_struct_argument_with_array_and_nested_fields(backend):
    p = Particle(m=10.0, x=wp.vec3(1, 2, 3))
    p.ids = wp.array([5, 6, 7], dtype=int)
    p.inner.k = 1
    out = wp.zeros(3, dtype=float)
    wp.launch(use_particle, 3, [p, out], backend=backend)
    np.testing.assert_allclose(out.numpy(), [40, 42, 44])


@wp.kernel
def count_ids(p: Particle, out: wp.array(dtype=int)):
    out[0] = p.ids.shape[0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_unset_array_field_is_empty(backend):
    out = wp.full(1, 9, dtype=int)
    wp.launch(count_ids, 1, [Particle(), out], backend=backend)
    assert out.numpy()[0] == 0


def test_wrong_struct_argument():
    with pytest.raises(KdslLaunchError, match=r"argument 0 'p'.*expected struct<Particle>"):
        wp.launch(count_ids, 1, [Inner(), wp.zeros(1, dtype=int)])


@wp.kernel
def write_fields(a: wp.array(dtype=Rec)):
    i = wp.tid()
    a[i].a = wp.int8(-i)
    a[i].h = wp.float16(0.5) * wp.float16(i)
    a[i].d = wp.float64(i) + 0.25
    a[i].on = i % 2 == 1
    a[i].v = wp.vec3(float(i), 2.0, 3.0)
    a[i].inner.y = float(i) * 2.0
    a[i].inner.k = wp.int8(i + 1)
    a[i].m = wp.mat22d(1.0, 2.0, 3.0, wp.float64(i))
    a[i].u = wp.uint16(65535 - i)


@pytest.mark.parametrize("backend", BACKENDS)
def test_kernel_writes_fields_numpy_reads_them(backend):
    """The backends' field offsets are NumPy's (the struct's numpy_dtype)."""
    n = 5
    a = wp.zeros(n, dtype=Rec)
    wp.launch(write_fields, n, [a], backend=backend)
    got = a.numpy()
    assert got.dtype == Rec.numpy_dtype()
    i = np.arange(n)
    assert list(got["a"]) == list(-i)
    np.testing.assert_array_equal(got["h"], (0.5 * i).astype(np.float16))
    np.testing.assert_array_equal(got["d"], i + 0.25)
    assert list(got["on"]) == [False, True, False, True, False]
    np.testing.assert_array_equal(got["v"], np.stack([i, 2 + 0 * i, 3 + 0 * i], 1))
    np.testing.assert_array_equal(got["inner"]["y"], 2.0 * i)
    assert list(got["inner"]["k"]) == list(i + 1)
    np.testing.assert_array_equal(got["m"][:, 1, 1], i)
    assert list(got["u"]) == list(65535 - i)
    assert isinstance(a[1], Rec) and a[1].inner.k == 2 and len(a.list()) == n


@wp.kernel
def read_fields(a: wp.array(dtype=Rec), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    r = a[i]
    out[i] = (wp.float64(r.a) + wp.float64(r.h) + r.d + wp.float64(r.v[1]) + r.m[1, 0]
              + wp.float64(r.inner.k) + wp.float64(r.u))  # fmt: skip
    if r.on:
        out[i] = -out[i]


@pytest.mark.parametrize("backend", BACKENDS)
def test_numpy_writes_fields_kernel_reads_them(backend):
    n = 4
    host = np.zeros(n, Rec.numpy_dtype())
    host["a"], host["h"], host["d"] = [1, -2, 3, -4], [0.5, 1.5, 2.5, 3.5], [10, 20, 30, 40]
    host["v"][:, 1], host["m"][:, 1, 0], host["inner"]["k"] = 100, 1000, [7, 8, 9, 10]
    host["u"], host["on"] = [1, 2, 3, 60000], [False, True, False, False]
    a = wp.array(host, dtype=Rec)
    out = wp.zeros(n, dtype=wp.float64)
    wp.launch(read_fields, n, [a, out], backend=backend)
    want = host["a"] + host["h"] + host["d"] + 100 + 1000 + host["inner"]["k"] + host["u"]
    np.testing.assert_array_equal(out.numpy(), np.where(host["on"], -want, want))


def test_array_constructors_of_structs():
    p = Rec(d=2.5, v=wp.vec3(1, 2, 3))
    a = wp.full(3, p, dtype=Rec)
    assert a.dtype is Rec and a[2] == p
    b = wp.array([p, Rec(), p], dtype=Rec)
    assert b[1] == Rec() and b[2].d == 2.5
    c = wp.array(b.numpy(), dtype=Rec)
    assert c[0] == p
    a.zero_()
    assert a[0] == Rec()
    a[1] = p
    assert a[1] == p
    with pytest.raises(wp.KdslError, match="struct holding arrays"):
        wp.zeros(2, dtype=Particle)


def test_struct_array_padding_bytes_are_zero():
    # Records have padding (Rec: 80 bytes, fields 63); zeros and full write every byte,
    # so a record array's bytes are the same on every device (the cuda test compares them).
    np.full(1 << 16, 0xFF, np.uint8)  # leave non-zero bytes behind in freed memory
    assert not any(wp.zeros(64, dtype=Rec).numpy().tobytes())
    p = Rec(d=1.5)
    expected = np.zeros(8, wp.zeros(1, dtype=Rec).numpy().dtype)
    expected["d"] = 1.5
    assert wp.full(8, p, dtype=Rec).numpy().tobytes() == expected.tobytes()


def test_wrong_numpy_layout_is_refused():
    packed = np.zeros(2, np.dtype([("y", "f4"), ("k", "i1")]))  # 5 bytes, not 8
    with pytest.raises(KdslLaunchError, match="NumPy dtype"):
        wp.launch(count_inner, 2, [packed], device="cpu")


@wp.kernel
def count_inner(a: wp.array(dtype=Inner)):
    a[0].k = wp.int8(1)


# --- located errors in kernels ---------------------------------------------------------


def _compile_error(fn) -> KdslTypeError:
    with pytest.raises(KdslTypeError) as e:
        wp.kernel(fn).build_module()
    return e.value


def test_unknown_field_is_located():
    def k(p: Particle):
        x = p.mass  # UNKNOWN-FIELD

    e = _compile_error(k)
    assert "has no field 'mass'" in str(e) and e.loc.line == _line("# UNKNOWN-FIELD")


def test_wrong_field_type_is_located():
    def k(p: Particle):
        q = p
        q.x = 1.0  # WRONG-TYPE

    e = _compile_error(k)
    assert "vec<3, f32>" in str(e) and e.loc.line == _line("# WRONG-TYPE")


def test_constructor_errors_are_located():
    def k(a: wp.array(dtype=float)):
        p = Inner(w=1.0)  # BAD-KEYWORD

    e = _compile_error(k)
    assert "'w'" in str(e) and e.loc.line == _line("# BAD-KEYWORD")

    def k2(a: wp.array(dtype=float)):
        p = Inner(1.0, wp.int8(1), 3)  # TOO-MANY

    assert _compile_error(k2).loc.line == _line("# TOO-MANY")

    def k3(a: wp.array(dtype=float)):
        p = Particle()  # NO-ARRAY

    e = _compile_error(k3)
    assert "Particle.ids is an array" in str(e) and e.loc.line == _line("# NO-ARRAY")


def test_atomics_on_struct_arrays_are_refused():
    def k(a: wp.array(dtype=Inner)):
        wp.atomic_add(a, 0, Inner())  # ATOMIC

    e = _compile_error(k)
    assert e.loc.line == _line("# ATOMIC")


def test_printed_ir_defines_structs_and_parses_back():
    from kdsl.ir import parse_module, print_module

    m = write_fields.build_module()
    text = print_module(m)
    inner, rec = Inner.__kdsl_type__.name, Rec.__kdsl_type__.name  # Inner_2... when taken
    assert re.search(rf"^struct {inner} \{{y: f32, k: i8\}}", text, re.M)
    assert text.index(f"struct {inner} ") < text.index(f"struct {rec} ")
    assert print_module(parse_module(text)) == text


def test_cuda_c_struct_layout_matches_numpy():
    """NVRTC checks sizeof/alignof/offsetof of the emitted C structs against numpy_dtype."""
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate
    from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

    m = write_fields.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    src = generate(m, [write_fields.key]).text
    names = {n: c for c, n in re.findall(r"struct (k_(\w+?)_\d+) \{", src)}
    # Some NVRTC builds (the one on the GPU machine) reject __builtin_offsetof; the
    # offsets are then checked by the cuda read-back test instead.
    try:
        nvrtc.compile_source(
            'struct P { int a; float b; };\nstatic_assert(__builtin_offsetof(P, b) == 4, "");\n',
            "sm_90",
        )
        offsets = True
    except wp.KdslError:
        offsets = False
    checks = []
    for cls in (Rec, Inner):
        st, dt, c = cls.__kdsl_type__, cls.numpy_dtype(), names[cls.__kdsl_type__.name]
        checks.append(f'static_assert(sizeof({c}) == {dt.itemsize}, "size");')
        checks.append(f'static_assert(alignof({c}) == {dt.alignment}, "align");')
        for k, (fname, _) in enumerate(st.fields if offsets else ()):
            off = dt.fields[fname][1]
            checks.append(f'static_assert(__builtin_offsetof({c}, f{k}) == {off}, "{fname}");')
    nvrtc.compile_source(src + "\n".join(checks) + "\n", "sm_90")
    with pytest.raises(wp.KdslError):  # the checks can fail
        nvrtc.compile_source(src + f'static_assert(sizeof({names["Rec"]}) == 1, "x");\n', "sm_90")


# --- indexedarray ----------------------------------------------------------------------


@wp.kernel
def through_indices(a: wp.indexedarray(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i] + float(a.shape[0])
    a[i] = a[i] * 2.0


@wp.kernel
def through_indices_2d(a: wp.indexedarray2d(dtype=float), out: wp.array2d(dtype=float)):
    i, j = wp.tid()
    out[i, j] = a[i, j]


@pytest.mark.parametrize("backend", BACKENDS)
def test_indexedarray_reads_and_writes_through_indices(backend):
    data = wp.array(np.arange(10, dtype=np.float32))
    ia = wp.indexedarray(data, [wp.array([7, 2, 5], dtype=int)])
    assert ia.shape == (3,)
    out = wp.zeros(3, dtype=float)
    wp.launch(through_indices, 3, [ia, out], backend=backend)
    np.testing.assert_array_equal(out.numpy(), [10, 5, 8])
    want = np.arange(10.0)
    want[[7, 2, 5]] *= 2
    np.testing.assert_array_equal(data.numpy(), want)
    np.testing.assert_array_equal(ia.numpy(), [14, 4, 10])


@pytest.mark.parametrize("backend", BACKENDS)
def test_indexedarray_mixes_indexed_and_plain_dims(backend):
    d = wp.array(np.arange(12, dtype=np.float32).reshape(3, 4))
    ia = wp.indexedarray(d, [None, wp.array([3, 0], dtype=int)])
    out = wp.zeros((3, 2), dtype=float)
    wp.launch(through_indices_2d, (3, 2), [ia, out], backend=backend)
    np.testing.assert_array_equal(out.numpy(), d.numpy()[:, [3, 0]])
    np.testing.assert_array_equal(ia.numpy(), out.numpy())


def test_indexedarray_errors():
    with pytest.raises(wp.KdslError, match="int32"):
        wp.indexedarray(wp.zeros(3), [wp.zeros(2)])

    def k(a: wp.indexedarray(dtype=float)):
        x = a[0, 1]  # TWO-INDICES

    e = _compile_error(k)
    assert "needs 1 indices" in str(e) and e.loc.line == _line("# TWO-INDICES")


@pytest.mark.cuda
@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
def test_cuda_struct_arguments_arrays_and_indexed_arrays():
    dev = "cuda:0"
    p = Particle(m=10.0, x=wp.vec3(1, 2, 3))
    p.ids = wp.array([5, 6, 7], dtype=int, device=dev)
    p.inner.k = 1
    out = wp.zeros(3, dtype=float, device=dev)
    wp.launch(use_particle, 3, [p, out], device=dev)
    np.testing.assert_allclose(out.numpy(), [40, 42, 44])
    a, ref = wp.zeros(5, dtype=Rec, device=dev), wp.zeros(5, dtype=Rec)
    wp.launch(write_fields, 5, [a], device=dev)
    wp.launch(write_fields, 5, [ref], device="cpu")
    assert a.numpy().tobytes() == ref.numpy().tobytes()  # same bytes as the cpu backend
    a[1] = Rec(d=2.5)
    a.fill_(Rec(d=1.5))
    assert a[3] == Rec(d=1.5)
    a.zero_()
    assert a[0] == Rec()
    data = wp.array(np.arange(10, dtype=np.float32), device=dev)
    ia = wp.indexedarray(data, [wp.array([7, 2, 5], dtype=int, device=dev)])
    wp.launch(through_indices, 3, [ia, out], device=dev)
    np.testing.assert_array_equal(out.numpy(), [10, 5, 8])
