"""The seed kernels (Warp's examples) compile to the expected IR."""

import pytest

import kdsl as wp
from kdsl.ir.types import F32, ArrayType, VectorType


@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3),
              f: wp.array(dtype=wp.vec3), w: wp.array(dtype=float),
              gravity: wp.vec3, dt: float):  # fmt: skip
    tid = wp.tid()
    x0 = x[tid]
    v0 = v[tid]
    f_ext = f[tid]
    inv_mass = w[tid]
    # Semi-implicit Euler step
    v1 = v0 + (f_ext * inv_mass + gravity) * dt
    x1 = x0 + v1 * dt
    x[tid] = x1
    v[tid] = v1


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def matmul(a: wp.array2d(dtype=float), b: wp.array2d(dtype=float), c: wp.array2d(dtype=float)):
    i, j = wp.tid()
    K = a.shape[0]
    s = wp.float32(0)
    for k in range(K):
        s += a[i, k] * b[k, j]
    c[i, j] = s


@wp.func
def rosenbrock(x: float, y: float):
    return (1.0 - x) ** 2.0 + 100.0 * (y - x**2.0) ** 2.0


@wp.kernel
def eval_rosenbrock(xs: wp.array(dtype=wp.vec2), z: wp.array(dtype=float)):
    i = wp.tid()
    x = xs[i]
    z[i] = rosenbrock(x[0], x[1])


@wp.kernel
def nbody(pos: wp.array(dtype=wp.vec3), vel: wp.array(dtype=wp.vec3), mass: wp.array(dtype=float),
          dt: float, eps: float):  # fmt: skip
    i = wp.tid()
    p = pos[i]
    acc = wp.vec3()
    for j in range(len(pos)):
        if j == i:
            continue
        d = pos[j] - p
        r2 = wp.dot(d, d) + eps * eps
        inv = 1.0 / (r2 * wp.sqrt(r2))
        acc += d * (mass[j] * inv)
    vel[i] = vel[i] + acc * dt


def test_integrate(build_text, check_ir):
    assert integrate.arg_types[0] == ArrayType(VectorType(3, F32), 1)
    check_ir(build_text(integrate), """
        CHECK: func.func @integrate_{{.*}}(%x: array<vec<3, f32>, 1>, {{.*}}%dt: f32) -> () {kind = "kernel"}
        CHECK-NEXT: %tid = kd.tid {dim = 0, ndim = 1} : i32
        CHECK: %inv_mass = kd.load %w, %tid : f32
        CHECK: arith.mul %f_ext, %inv_mass : vec<3, f32>
        CHECK: %v1 = arith.add %v0
        CHECK: kd.store %x1, %x, %tid
        CHECK-NEXT: kd.store %v1, %v, %tid
        CHECK-NEXT: func.return
    """)  # fmt: skip


def test_saxpy(build_text, check_ir):
    check_ir(
        build_text(saxpy),
        """
        CHECK: %i = kd.tid
        CHECK-NEXT: %0 = kd.load %x, %i : f32
        CHECK-NEXT: %1 = arith.mul %a, %0 : f32
        CHECK-NEXT: %2 = kd.load %y, %i : f32
        CHECK-NEXT: %3 = arith.add %1, %2 : f32
        CHECK-NEXT: kd.store %3, %y, %i
    """,
    )
    assert saxpy.tid_ndim == 1
    assert saxpy.arg_names == ["x", "y", "a"]


def test_matmul(build_text, check_ir):
    check_ir(
        build_text(matmul),
        """
        CHECK: %i = kd.tid {dim = 0, ndim = 2} : i32
        CHECK-NEXT: %j = kd.tid {dim = 1, ndim = 2} : i32
        CHECK-NEXT: %K = kd.array_shape %a {dim = 0} : i32
        CHECK-NEXT: %s = arith.constant {value = 0.0} : f32
        CHECK: %s_1 = scf.for {{%[0-9]+}}, %K, {{%[0-9]+}}, %s : f32 {
        CHECK-NEXT: ^bb(%k: i32, %s_2: f32):
        CHECK: kd.load %a, %i, %k : f32
        CHECK: kd.load %b, %k, %j : f32
        CHECK: scf.yield %s_3
        CHECK: kd.store %s_1, %c, %i, %j
    """,
    )
    assert matmul.tid_ndim == 2


def test_rosenbrock(build_text, check_ir):
    check_ir(
        build_text(eval_rosenbrock),
        """
        CHECK: vec.extract %x
        CHECK: func.call {{.*}} {callee = "rosenbrock_{{.*}}"} : f32
        CHECK: func.func @rosenbrock_{{.*}}(%x: f32, %y: f32) -> (f32) {kind = "func"}
        CHECK: arith.pow
        CHECK: func.return
    """,
    )
    assert rosenbrock(0.5, 0.25) == pytest.approx(0.25)


def test_nbody(build_text, check_ir):
    check_ir(
        build_text(nbody),
        """
        CHECK: %acc = vec.splat
        CHECK: kd.array_shape %pos {dim = 0}
        CHECK: scf.for
        CHECK: ^bb(%j: i32, %acc_{{[0-9]}}: vec<3, f32>):
        CHECK: arith.cmp %j, %i {pred = "eq"}
        CHECK: scf.if
        CHECK: vec.dot %d, %d : f32
        CHECK: math.sqrt
        CHECK: scf.yield
        CHECK: kd.store
    """,
    )
