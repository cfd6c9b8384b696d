"""Atomic builtins in the frontend: the ops they emit, `+=` on elements, located errors."""

from __future__ import annotations

import kdsl as wp
from kdsl.ir import parse_module, print_module
from tests.frontend.located_errors import expect_error_at_marker


@wp.kernel
def every_kind(a: wp.array(dtype=wp.int32), f: wp.array2d(dtype=float)):
    i = wp.tid()
    wp.atomic_and(a, i, 6)
    wp.atomic_or(a, i, 1)
    wp.atomic_xor(a, i, 3)
    wp.atomic_exch(a, i, 9)
    old = wp.atomic_cas(f, i, 0, 1.5, 2.5)
    f[i, 1] += old
    f[i, 1] -= 1.0
    f[i, 0] *= 2.0


def test_atomic_builtins_emit_the_atomic_ops(check_ir):
    text = print_module(every_kind.build_module())
    check_ir(text, """
        CHECK: kd.atomic_rmw {{.*}} {kind = "and"} : i32
        CHECK: kd.atomic_rmw {{.*}} {kind = "or"} : i32
        CHECK: kd.atomic_rmw {{.*}} {kind = "xor"} : i32
        CHECK: kd.atomic_rmw {{.*}} {kind = "exch"} : i32
        CHECK: %old = kd.atomic_cas {{.*}} : f32
        CHECK: kd.atomic_rmw %old, %f, {{.*}} {kind = "add"} : f32
        CHECK: kd.atomic_rmw {{.*}} {kind = "sub"} : f32
        CHECK: kd.load
        CHECK: arith.mul
        CHECK: kd.store
    """)
    assert print_module(parse_module(text)) == text


def test_atomic_type_errors_are_located():
    @wp.kernel
    def and_on_floats(a: wp.array(dtype=float)):
        wp.atomic_and(a, 0, 1.0)  # <-

    @wp.kernel
    def cas_wrong_type(a: wp.array(dtype=wp.int32), x: float):
        wp.atomic_cas(a, 0, 1, x)  # <-

    @wp.kernel
    def too_few_indices(a: wp.array2d(dtype=wp.int32)):
        wp.atomic_add(a, 0, 1)  # <-

    @wp.kernel
    def not_an_array(x: float):
        wp.atomic_add(x, 0, 1.0)  # <-

    expect_error_at_marker(and_on_floats, "atomic and needs an integer array", caret=False)
    expect_error_at_marker(cas_wrong_type,
                           "compare value and a new value of the array's type", caret=False)
    expect_error_at_marker(too_few_indices, "needs 2 indices, got 1", caret=False)
    expect_error_at_marker(not_an_array, "needs an array first", caret=False)
