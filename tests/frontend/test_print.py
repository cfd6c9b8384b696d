"""print() and printf() in kernels: output on interp and cpu, format checks, escaping.

The expected texts of Warp-style values were printed by Warp 1.19's own ``print``
on CPU (vectors end with a space, matrices print one row per line).
"""

from __future__ import annotations

import math

import pytest

import kdsl as wp
from kdsl.ir import parse_module, print_module
from kdsl.ir.ops_print import FormatError, c_format, format_values, parse_format
from tests.frontend.located_errors import expect_error_at_marker

BACKENDS = ("interp", "cpu")
LABEL = "const text"
NASTY = 'q="x" \\ */ /* ?? 100%%\n%d\t\n'


@wp.kernel
def show(x: float, i: int, d: wp.float64, u: wp.uint64):
    print(x)
    print(i)
    print(wp.vec3(1.0, 2.5, -3.0))
    print(wp.mat22(1.0, 2.0, 3.0, 4.0))
    print(wp.quat(0.0, 0.0, 0.0, 1.0))
    print(wp.transform(wp.vec3(1.0, 2.0, 3.0), wp.quat(0.0, 0.0, 0.0, 1.0)))
    print(x > 1.0, wp.vec3i(1, -2, 3), wp.float16(1.5), wp.int8(-5), u)
    print("x =", x, "d =", d, LABEL, sep="|", end="!\n")
    print(f"x={x:.3f} i={i:5d} hex={i:#x} pad={i:<4d}| {d:+.2e} {x}")
    wp.printf("x=%f i=%d %% \"q\" \\ */\n", x, i)
    wp.printf("%g %5.2f %e %lld %s\n", x, x, d, wp.int64(7), x < 0.0)
    wp.printf("%x %u %c%c %o %X\n", -1, wp.int8(-1), 72, 105, 8, u)
    wp.printf("%g %F %e %5.1f|\n", math.inf, -math.inf * d, 1e300 * d, wp.float16(-0.0))


EXPECTED = """\
1.5
42
1 2.5 -3 
1 2 
3 4 
0 0 0 1
(1 2 3) (0 0 0 1)
True 1 -2 3  1.5 -5 18446744073709551615
x =|1.5|d =|-0.25|const text!
x=1.500 i=   42 hex=0x2a pad=42  | -2.50e-01 1.5
x=1.500000 i=42 % "q" \\ */
1.5  1.50 -2.500000e-01 7 False
ffffffff 255 Hi 10 FFFFFFFFFFFFFFFF
inf INF -2.500000e+299  -0.0|
"""  # noqa: W291 - Warp's vector and matrix formats end lines with a space


@pytest.mark.parametrize("backend", BACKENDS)
def test_print_and_printf_output(backend, capfd):
    wp.launch(show, 1, [1.5, 42, -0.25, 2**64 - 1], backend=backend)
    out = capfd.readouterr().out
    assert out == EXPECTED


@wp.kernel
def per_thread(a: wp.array(dtype=wp.int32)):
    i = wp.tid()
    wp.printf("thread %d of %d\n", i, a.shape[0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_output_is_in_order_with_python_prints(backend, capfd):
    n = 64
    a = wp.zeros(n, dtype=wp.int32)
    print("before")
    wp.launch(per_thread, n, [a], backend=backend)
    print("after")
    lines = capfd.readouterr().out.splitlines()
    assert lines[0] == "before" and lines[-1] == "after"
    # Threads may print in any order; each line is whole.
    assert sorted(lines[1:-1]) == sorted(f"thread {i} of {n}" for i in range(n))


@wp.func
def helper(x: float) -> float:
    print("in helper", x)
    return x * 2.0


@wp.kernel
def calls_helper(a: wp.array(dtype=float)):
    a[0] = helper(a[0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_print_in_a_function(backend, capfd):
    a = wp.array([0.5], dtype=float)
    wp.launch(calls_helper, 1, [a], backend=backend)
    assert capfd.readouterr().out == "in helper 0.5\n"
    assert a.numpy()[0] == 1.0


def test_format_survives_the_ir_text_form():
    @wp.kernel
    def k(i: int):
        wp.printf(NASTY, i)

    text = print_module(k.build_module())
    assert print_module(parse_module(text)) == text
    (op,) = [o for o in parse_module(text).walk() if o.name == "kd.print"]
    assert op.attrs["format"] == NASTY


def test_reference_formatter_follows_c():
    fmt = "%d|%5u|%-4x|%#X|%#x|%08.3f|%+e|%G|%c|%s|%%"
    assert format_values(fmt, [-3, 7, 255, 255, 0, 3.14159, 1.0, 1e-10, 65, True]) == (
        "-3|    7|ff  |0XFF|0|0003.142|+1.000000e+00|1E-10|A|True|%"
    )
    assert c_format("%d %i %u %o %x %X %f %s %c %%") == "%lld %lli %llu %llo %llx %llX %f %s %c %%"
    assert parse_format("a%%b") == ["a", "%", "b"]
    nan = float("nan")
    assert format_values("%f %5.1e %G", [nan, -nan, -nan]) == "nan   nan -NAN".replace(
        "  nan", " -nan"
    )
    for bad in ("%n", "%p", "%*d", "%.*f", "%a", "%", "50%!", "%#o"):
        with pytest.raises(FormatError):
            parse_format(bad)


def test_printf_checks_argument_types():
    @wp.kernel
    def int_as_float(i: int):
        wp.printf("%f\n", i)  # <-

    @wp.kernel
    def float_as_int(x: float):
        wp.printf("%d\n", x)  # <-

    @wp.kernel
    def int_as_string(i: int):
        wp.printf("%s\n", i)  # <-

    @wp.kernel
    def vector_arg(x: float):
        wp.printf("%f\n", wp.vec3(x, x, x))  # <-

    @wp.kernel
    def string_arg(x: float):
        wp.printf("%d\n", "text")  # <-

    expect_error_at_marker(int_as_float, "'%f' needs a float, got a i32")
    expect_error_at_marker(float_as_int, "'%d' needs an integer, got a f32")
    expect_error_at_marker(int_as_string, "'%s' prints a bool")
    expect_error_at_marker(vector_arg, "cannot format a vec<3, f32>")
    expect_error_at_marker(string_arg, "no string values")


def test_printf_checks_the_format():
    @wp.kernel
    def too_few(i: int):
        wp.printf("%d %d\n", i)  # <-

    @wp.kernel
    def too_many(i: int):
        wp.printf("%d\n", i, i)  # <-

    @wp.kernel
    def star_width(i: int):
        wp.printf("%*d\n", i, i)  # <-

    @wp.kernel
    def not_constant(i: int):
        wp.printf(i)  # <-

    @wp.kernel
    def bad_end(i: int):
        print(i, end=i)  # <-

    expect_error_at_marker(too_few, "has 2 conversions but 1 arguments")
    expect_error_at_marker(too_many, "has 1 conversions but 2 arguments")
    expect_error_at_marker(star_width, "'*' widths")
    expect_error_at_marker(not_constant, "must be a string constant")
    expect_error_at_marker(bad_end, "print's end must be a string constant")
