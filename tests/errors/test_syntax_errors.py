"""Python constructs the kernel language rejects, each with a located KdslSyntaxError."""
# ruff: noqa: C416, SIM105, F401, E731

import pytest

import kdsl as wp
from kdsl.errors import KdslSyntaxError

FLOATS = wp.array(dtype=float)


def test_list_comprehension(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = [i for i in range(3)]  # <-

    expect_error(k, KdslSyntaxError, "list comprehension")


def test_dict_comprehension(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = {i: i for i in range(3)}  # <-

    expect_error(k, KdslSyntaxError, "dict comprehension")


def test_set_comprehension(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = {i for i in range(3)}  # <-

    expect_error(k, KdslSyntaxError, "set comprehension")


def test_generator_expression(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = sum(i for i in range(3))  # <-

    expect_error(k, KdslSyntaxError, "generator expression")


def test_try_except(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        try:  # <-
            a[0] = 1.0
        except Exception:
            pass

    expect_error(k, KdslSyntaxError, "try/except")


def test_lambda(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        f = lambda x: x  # <-

    expect_error(k, KdslSyntaxError, "lambda")


def test_with(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        with a:  # <-
            pass

    expect_error(k, KdslSyntaxError, "with")


def test_global(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        global FLOATS  # <-

    expect_error(k, KdslSyntaxError, "global")


def test_nonlocal(expect_error):
    y = 1.0

    @wp.kernel
    def k(a: FLOATS):
        nonlocal y  # <-
        a[0] = y

    expect_error(k, KdslSyntaxError, "nonlocal")


def test_string(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        s = "hello"  # <-

    expect_error(k, KdslSyntaxError, "strings are not supported")


def test_list_literal(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = [1.0, 2.0]  # <-

    expect_error(k, KdslSyntaxError, "list")


def test_dict_literal(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = {"a": 1.0}  # <-

    expect_error(k, KdslSyntaxError, "dict")


def test_starred_args(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        v = wp.vec3(*a)  # <-

    expect_error(k, KdslSyntaxError, "starred")


def test_yield(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        yield 1  # <-

    expect_error(k, KdslSyntaxError, "yield")


def test_async(expect_error):
    @wp.kernel
    async def k(a: FLOATS):  # <-
        pass

    expect_error(k, KdslSyntaxError, "async")


def test_nested_def(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        def g(x):  # <-
            return x

    expect_error(k, KdslSyntaxError, "cannot be defined inside")


def test_nested_class(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        class C:  # <-
            pass

    expect_error(k, KdslSyntaxError, "a class cannot be defined")


def test_del(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        x = 1.0
        del x  # <-

    expect_error(k, KdslSyntaxError, "del")


def test_assert(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        assert a[0] > 0.0  # <-

    expect_error(k, KdslSyntaxError, "assert")


def test_import(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        import math  # <-

    expect_error(k, KdslSyntaxError, "import")


def test_walrus(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        if (n := 3) > 2:  # <-
            pass

    expect_error(k, KdslSyntaxError, "walrus")


def test_return_value_from_kernel(expect_error):
    @wp.kernel
    def k(a: FLOATS):
        return 1.0  # <-

    expect_error(k, KdslSyntaxError, "kernel cannot return a value")


def test_assign_to_array_argument(expect_error):
    @wp.kernel
    def k(a: FLOATS, b: FLOATS):
        a = b  # <-

    expect_error(k, KdslSyntaxError, "cannot assign to the array 'a'")


def test_direct_recursion(expect_error):
    @wp.func
    def fact(n: int):
        if n <= 1:
            return 1
        return n * fact(n - 1)  # <-

    @wp.kernel
    def k(a: FLOATS):
        a[0] = float(fact(3))

    expect_error(k, KdslSyntaxError, "recursion", where=fact)


def test_mutual_recursion(expect_error):
    @wp.func
    def ping(n: int) -> int:
        return pong(n)

    @wp.func
    def pong(n: int) -> int:
        return ping(n)  # <-

    @wp.kernel
    def k(a: FLOATS):
        a[0] = float(ping(3))

    err = expect_error(k, KdslSyntaxError, "recursion", where=pong)
    assert "ping -> pong -> ping" in err.message


def test_func_may_end_without_return(expect_error):
    @wp.func
    def f(x: float):  # <-
        if x > 0.0:
            return x

    @wp.kernel
    def k(a: FLOATS):
        a[0] = f(a[0])

    expect_error(k, KdslSyntaxError, "may end without returning", where=f)


def test_calling_a_kernel_from_python():
    @wp.kernel
    def k(a: FLOATS):
        pass

    with pytest.raises(wp.KdslError, match=r"kdsl\.launch"):
        k(None)
