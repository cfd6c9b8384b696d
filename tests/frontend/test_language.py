"""Language features lowered to structured IR (checked on the printed module)."""
# ruff: noqa: UP018, RUF046

import math

import numpy as np

import kdsl as wp
from kdsl.ir.types import F32, I32, VectorType

FLOATS = wp.array(dtype=float)
INTS = wp.array(dtype=int)
SCALE = wp.constant(2.5)
OFFSET = wp.vec3(1.0, 2.0, 3.0)
N_UNROLL = 3


@wp.func
def twice(x: float):
    return 2.0 * x


@wp.func
def twice(x: int):  # noqa: F811 - an overload
    return 2 * x


@wp.func
def divmod_(a: int, b: int):
    return a / b, a % b


@wp.kernel(enable_backward=False)
def k_overloads(a: FLOATS, b: INTS):
    i = wp.tid()
    a[i] = twice(a[i])
    b[i] = twice(b[i])
    q, r = divmod_(b[i], 3)
    b[i] = q + r


def test_overloads_and_tuple_returns(build_text, check_ir):
    text = build_text(k_overloads)
    check_ir(
        text,
        """
        CHECK: func.call {{.*}} : f32
        CHECK: func.call {{.*}} : i32
        CHECK: %q, %r = func.call {{.*}} : i32, i32
        CHECK: func.func @twice_{{.*}}(%x: f32) -> (f32)
        CHECK: func.func @twice_{{.*}}(%x: i32) -> (i32)
        CHECK: func.func @divmod__{{.*}} -> (i32, i32)
        CHECK: arith.div %a, %b : i32
        CHECK: arith.mod %a, %b : i32
    """,
    )
    assert k_overloads.options["enable_backward"] is False


@wp.kernel
def k_early_return(a: FLOATS, n: int):
    i = wp.tid()
    if i >= n:
        return
    a[i] = 1.0


def test_early_return_becomes_if_else(build_text, check_ir):
    check_ir(
        build_text(k_early_return),
        """
        CHECK: arith.cmp %i, %n {pred = "ge"}
        CHECK: scf.if
        CHECK: } {
        CHECK: kd.store
        CHECK: func.return
    """,
    )


@wp.kernel
def k_short_circuit(a: FLOATS, n: int):
    i = wp.tid()
    if i < n and a[i] > 0.0:
        a[i] = 0.0


def test_and_is_short_circuit(build_text, check_ir):
    check_ir(
        build_text(k_short_circuit),
        """
        CHECK: arith.cmp %i, %n {pred = "lt"}
        CHECK-NEXT: scf.if {{%[0-9]+}} : bool {
        CHECK-NEXT: kd.load %a, %i
        CHECK: scf.yield
        CHECK: } {
        CHECK: arith.constant {value = false}
    """,
    )


@wp.kernel
def k_break(a: FLOATS, n: int):
    i = wp.tid()
    total = float(0)
    for k in range(n):
        if a[k] < 0.0:
            break
        if a[k] == 0.0:
            continue
        total += a[k]
    a[i] = total


def test_break_makes_while_and_continue_guards(build_text, check_ir):
    check_ir(
        build_text(k_break),
        """
        CHECK-NOT: scf.for
        CHECK: scf.while
        CHECK: scf.condition
        CHECK: arith.cmp {{.*}} {pred = "lt"}
        CHECK: scf.if
        CHECK: arith.add
        CHECK: kd.store
    """,
    )


@wp.kernel
def k_while(a: FLOATS):
    i = wp.tid()
    x = a[i]
    steps = int(0)
    while x > 1.0:
        x = x / 2.0
        steps += 1
    a[i] = x + float(steps)


def test_while_carries_values(build_text, check_ir):
    check_ir(
        build_text(k_while),
        """
        CHECK: %steps_1, %x_1 = scf.while %steps, %x : i32, f32 {
        CHECK: scf.condition
        CHECK: arith.div {{.*}} : f32
        CHECK: scf.yield
    """,
    )


@wp.kernel
def k_static_and_closure(a: FLOATS):
    i = wp.tid()
    s = float(0)
    for k in range(wp.static(N_UNROLL)):
        s += float(k) * SCALE
    v = OFFSET * s
    a[i] = v.y + math.pi + wp.static(N_UNROLL * 2.0)


def test_static_unroll_and_constants(build_text, check_ir):
    text = build_text(k_static_and_closure)
    check_ir(
        text,
        """
        CHECK-NOT: scf.for
        CHECK: arith.constant {value = 2.5} : f32
        CHECK: arith.constant {value = 2.5} : f32
        CHECK: arith.constant {value = 2.5} : f32
        CHECK: vec.construct {{.*}} : vec<3, f32>
        CHECK: arith.constant {value = 3.14159{{[0-9]*}}} : f32
        CHECK: arith.constant {value = 6.0} : f32
    """,
    )


@wp.kernel
def k_vectors(a: wp.array(dtype=wp.vec3), m: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    v = a[i]
    v.x = 1.0
    v[1] += 2.0
    mm = m[i]
    mm[0, 1] = v.z
    mm[2][0] = 3.0
    w = mm @ v + mm * v
    r = wp.vec3(mm[0][0])
    u = wp.normalize(wp.cross(w, r)) * wp.length(v)
    k = i % 3
    u[k] = wp.dot(u, v)
    t = wp.transpose(mm) * wp.mat33(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    a[i] = u + t[0] + wp.vec3(wp.vec3d(1.0, 2.0, 3.0))


def test_vectors_and_matrices(build_text, check_ir):
    check_ir(
        build_text(k_vectors),
        """
        CHECK: %v_1 = vec.insert %v, {{.*}} : vec<3, f32>
        CHECK: vec.insert %mm, {{%[0-9]+}}, {{%[0-9]+}}, {{%[0-9]+}} : mat<3, 3, f32>
        CHECK: vec.extract %mm_1, {{%[0-9]+}} : vec<3, f32>
        CHECK: vec.matmul
        CHECK-NEXT: vec.matmul
        CHECK: vec.splat
        CHECK: vec.cross
        CHECK: vec.normalize
        CHECK: vec.insert %u, {{.*}}, %k
        CHECK: vec.transpose
        CHECK: vec.matmul {{.*}} : mat<3, 3, f32>
        CHECK: arith.cast {{.*}} : vec<3, f32>
    """,
    )


@wp.kernel
def k_builtins(a: FLOATS, b: INTS):
    i = wp.tid()
    x = a[i]
    y = wp.clamp(x, 0.0, 1.0) + wp.min(x, 2.0) + max(x, 0.5) + abs(x) + wp.sign(x)
    y += wp.sqrt(x) + wp.exp(x) + wp.atan2(x, 1.0) + wp.pow(x, 3.0) + math.cos(x)
    y += wp.select(x > 0.0, 1.0, 2.0) + wp.where(x > 0.0, 1.0, 2.0)
    old = wp.atomic_add(a, 0, y)
    wp.atomic_max(b, 0, i)
    c = wp.load(a, i) + float(len(a)) + float(b.shape[0])
    n = int(x) // 2 - (i << 1) ^ 3
    if wp.isnan(c) or not wp.isfinite(old):
        c = 0.0
    a[i] = c if 0 < i < n else -c


def test_builtins(build_text, check_ir):
    check_ir(
        build_text(k_builtins),
        """
        CHECK: arith.max {{%[0-9]+}}, %x
        CHECK-NEXT: arith.min
        CHECK: math.abs %x
        CHECK: math.sign %x
        CHECK: math.atan2
        CHECK: math.cos
        CHECK: arith.select {{%[0-9a-z_]+}}, {{%[0-9]+}}, {{%[0-9]+}} : f32
        CHECK: %old = kd.atomic_rmw %y_{{[0-9]}}, %a, {{%[0-9]+}} {kind = "add"} : f32
        CHECK: kd.atomic_rmw %i, %b, {{%[0-9]+}} {kind = "max"} : i32
        CHECK: kd.array_shape %a {dim = 0}
        CHECK: arith.cast %x : i32
        CHECK: arith.floordiv
        CHECK: arith.shl
        CHECK: arith.xor
        CHECK: math.isnan
        CHECK: scf.if
        CHECK: arith.and
    """,
    )


@wp.kernel
def k_swap(a: FLOATS):
    i, j = wp.tid()
    x = a[i]
    y = a[j]
    x, y = y, x
    z = w = 1.0
    a[i] = x - y + z * w


def test_tuple_swap_and_chained(build_text, check_ir):
    check_ir(
        build_text(k_swap),
        """
        CHECK: %x = kd.load %a, %i
        CHECK: %y = kd.load %a, %j
        CHECK: arith.sub %y, %x
    """,
    )
    assert k_swap.tid_ndim == 2


def test_arg_types_and_key():
    assert k_vectors.arg_types[1].dtype.rows == 3
    assert k_swap.arg_types == [wp.array(dtype=float).__kdsl_type__]
    assert k_swap.key.startswith("k_swap_") and k_swap.key != k_while.key
    assert k_swap.source_file.endswith("test_language.py")
    assert VectorType(3, F32) == wp.vec3.__kdsl_type__ and I32.name == "i32"


def test_build_module_is_fresh():
    m1, m2 = k_swap.build_module(), k_swap.build_module()
    assert m1 is not m2 and m1.funcs[0] is not m2.funcs[0]


def test_python_scope_func_call():
    assert np.isclose(twice(1.5), 3.0)


@wp.kernel
def k_store_in_loop(out: FLOATS, n: int):
    for k in range(n):
        if k > 2:
            return
        out[k] = float(k)


def test_array_store_in_loop_is_not_carried(build_text, check_ir):
    check_ir(
        build_text(k_store_in_loop),
        """
        CHECK: scf.while
        CHECK-NOT: array<f32, 1>, bool
        CHECK: kd.store
        """,
    )
