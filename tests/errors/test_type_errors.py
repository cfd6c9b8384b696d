"""Typing and naming mistakes: each raises a located KdslTypeError or KdslNameError."""
# ruff: noqa: F811, RUF059, E741, F821

import kdsl as wp
from kdsl.errors import KdslNameError, KdslTypeError

FLOATS = wp.array(dtype=float)
FLOATS2 = wp.array(dtype=float, ndim=2)


def test_undefined_name(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = undefined_thing  # <-

    expect_error(k, KdslNameError, "name 'undefined_thing' is not defined")


def test_unknown_module_attribute(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = wp.nope(1.0)  # <-

    expect_error(k, KdslNameError, "has no attribute 'nope'")


def test_variable_changes_type(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = 1.0
        x = wp.vec3()  # <-

    expect_error(k, KdslTypeError, "changes type from f32 to vec<3, f32>")


def test_int_plus_float(expect_error):
    @wp.kernel
    def k(a: FLOATS, n: int):
        a[0] = a[0] + n  # <-

    expect_error(k, KdslTypeError, "cannot add f32 and i32")


def test_float_literal_with_int(expect_error):
    @wp.kernel
    def k(a: FLOATS, n: int):
        m = n * 2.5  # <-

    expect_error(k, KdslTypeError, "float literal 2.5")


def test_builtin_argument_count(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = wp.sin(1.0, 2.0)  # <-

    expect_error(k, KdslTypeError, "sin() takes 1 arguments, got 2")


def test_builtin_keyword_argument(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = wp.sin(x=1.0)  # <-

    expect_error(k, KdslTypeError, "takes no keyword arguments")


def test_func_argument_count(expect_error):
    @wp.func
    def f(x: float):
        return x

    @wp.kernel
    def k(a: FLOATS):
        a[0] = f(1.0, 2.0)  # <-

    expect_error(k, KdslTypeError, "f() takes 1 arguments, got 2")


def test_no_matching_overload(expect_error):
    @wp.func
    def g(x: float):
        return x

    @wp.func
    def g(x: wp.vec3):
        return x

    @wp.kernel
    def k(a: FLOATS):
        v = g(wp.vec2())  # <-

    expect_error(k, KdslTypeError, "no overload of g()")


def test_return_type_mismatch(expect_error):
    @wp.func
    def f(x: float):
        if x > 0.0:
            return x
        return 1  # <-

    @wp.kernel
    def k(a: FLOATS):
        a[0] = f(a[0])

    expect_error(k, KdslTypeError, "every return must agree", where=f)


def test_maybe_unassigned_after_if(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        if a[0] > 0.0:
            y = 1.0
        a[1] = y  # <-

    expect_error(k, KdslNameError, "may be unassigned")


def test_maybe_unassigned_after_loop(expect_error):
    @wp.kernel
    def k(a: FLOATS, n: int):
        for i in range(n):
            t = a[i]
        a[0] = t  # <-

    expect_error(k, KdslNameError, "'t' may be unassigned")


def test_loop_carried_type_change(expect_error):
    @wp.kernel
    def k(a: FLOATS, n: int):
        s = 0
        for i in range(n):
            s = a[i]  # <-

    expect_error(k, KdslTypeError, "changes type from i32 to f32")


def test_static_raises(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = wp.static(1 / 0)  # <-

    expect_error(k, KdslTypeError, "ZeroDivisionError")


def test_static_not_constant(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = wp.static(print)  # <-

    expect_error(k, KdslTypeError, "compile-time constant")


def test_vector_condition(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        v = wp.vec3()
        if v:  # <-
            a[0] = 1.0

    expect_error(k, KdslTypeError, "condition must be a bool or a number")


def test_index_scalar(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = a[0]
        a[1] = x[0]  # <-

    expect_error(k, KdslTypeError, "f32 cannot be indexed")


def test_too_many_indices(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = a[0, 1]  # <-

    expect_error(k, KdslTypeError, "too many indices")


def test_missing_annotation(expect_error):
    @wp.kernel
    def k(a: FLOATS, n):  # <-
        pass

    expect_error(k, KdslTypeError, "needs a type annotation")


def test_unsupported_annotation(expect_error):
    @wp.kernel
    def k(a: FLOATS, s: str):  # <-
        pass

    expect_error(k, KdslTypeError, "not a kdsl type")


def test_vector_constructor_count(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        v = wp.vec3(1.0, 2.0)  # <-

    expect_error(k, KdslTypeError, "takes 3 components, but 2 were given")


def test_bad_component(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        v = wp.vec3()
        a[0] = v.q  # <-

    expect_error(k, KdslTypeError, "no attribute '.q'")


def test_w_on_vec3(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        v = wp.vec3()
        a[0] = v.w  # <-

    expect_error(k, KdslTypeError, "no component '.w'")


def test_tid_five_dims(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        i, j, l, m, n = wp.tid()  # <-

    expect_error(k, KdslTypeError, "1 to 4 indices")


def test_tuple_in_variable(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        t = (1.0, 2.0)  # <-

    expect_error(k, KdslTypeError, "cannot store a tuple")


def test_unpack_count(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x, y = 1.0, 2.0, 3.0  # <-

    expect_error(k, KdslTypeError, "cannot unpack 3 values into 2 names")


def test_branch_type_mismatch(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        if a[0] > 0.0:  # <-
            z = 1.0
        else:
            z = 1
        a[0] = z

    expect_error(k, KdslTypeError, "variable 'z' is f32 on one branch and i32 on the other")


def test_ternary_arm_types(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        y = wp.vec3() if a[1] > 0.0 else a[0]  # <-

    expect_error(k, KdslTypeError, "both arms must have one type")


def test_store_wrong_dtype(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        a[0] = wp.vec3()  # <-

    expect_error(k, KdslTypeError, "cannot store")


def test_array_needs_all_indices_on_store(expect_error):
    @wp.kernel
    def k(a: FLOATS2):
        a[0] = 1.0  # <-

    expect_error(k, KdslTypeError, "2-d array needs 2 indices")


def test_error_inside_func_points_at_func(expect_error):
    @wp.func
    def f(x: float):
        return x + wp.vec3()  # <-

    @wp.kernel
    def k(a: FLOATS):
        a[0] = f(a[0])

    err = expect_error(k, KdslTypeError, "cannot add", where=f)
    assert "while compiling kernel 'k'" in str(err)
