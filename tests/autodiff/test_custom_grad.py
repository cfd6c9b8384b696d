"""Custom gradients (``@wp.func_grad``, ``@wp.func_replay``, ``wp.adjoint``): the frontend.

The IR contract the ``adjoint`` pass reads: the primal carries ``custom_grad`` (and
``custom_replay``); the gradient function takes ``(params..., adj_ret...)`` and
returns one adjoint per parameter. Gradient functions are run on ``interp`` on their
own, so these tests check the frontend without the pass; the end-to-end tests at
the bottom go through ``launch_adjoint``.
"""

from __future__ import annotations

import inspect
import re

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.interp.program import Program, ThreadContext
from kdsl.errors import KdslError, KdslSyntaxError, KdslTypeError
from kdsl.ir import Module, parse_module, print_module, verify_module
from kdsl.passes import run_pipeline
from kdsl.runtime.adjoint import launch_adjoint

FLOATS = wp.array(dtype=float)
KEEP = "inline{keep_custom_grad=true},fold,canonicalize,cse,dce"
MARK = "# <-"


def _marked_line(fn) -> int:
    lines, start = inspect.getsourcelines(fn)
    hits = [start + k for k, line in enumerate(lines) if MARK in line]
    assert len(hits) == 1, f"{fn.__name__} needs exactly one {MARK!r} marker"
    return hits[0]


def assert_located(err: KdslError, fn, fragment: str) -> None:
    """``err`` mentions ``fragment`` and points at the marked line of ``fn``'s source."""
    assert fragment in err.message, err.message
    assert err.loc is not None and err.loc.line == _marked_line(fn), (err.loc, str(err))
    assert "^" in str(err), str(err)


def _func(module: Module, prefix: str):
    hits = [f for f in module.funcs if f.attrs["sym_name"].startswith(prefix + "_")]
    assert len(hits) == 1, [f.attrs["sym_name"] for f in module.funcs]
    return hits[0]


def _run_func(module: Module, prefix: str, *args):
    """Call a function of ``module`` on ``interp`` (the module's other functions too)."""
    program = Program(module)
    name = _func(module, prefix).attrs["sym_name"]
    return ThreadContext(program, program.function(name), name).call(name, list(args))


# --- shared functions -----------------------------------------------------------------


@wp.func
def safe_sqrt(x: float):
    return wp.sqrt(x)


@wp.func_grad(safe_sqrt)
def adj_safe_sqrt(x: float, adj_ret: float):
    if x > 0.0:
        wp.adjoint[x] += 1.0 / (2.0 * wp.sqrt(x)) * adj_ret


@wp.func_replay(safe_sqrt)
def replay_safe_sqrt(x: float):
    return wp.sqrt(x)


@wp.kernel
def sqrt_kernel(a: FLOATS, b: FLOATS):
    i = wp.tid()
    b[i] = safe_sqrt(a[i])


@wp.func
def pair(x: float, y: float):
    return x * y, x + y


@wp.func_grad(pair)
def adj_pair(x: float, y: float, adj_ret0: float, adj_ret1: float):
    for _k in range(3):
        wp.adjoint[x] += adj_ret0
    if y < 0.0:
        return
    wp.adjoint[y] = wp.adjoint[x] * 2.0 + adj_ret1


@wp.func
def mixed(v: wp.vec3, n: int, m: wp.mat22, xs: FLOATS):
    return v[0] + float(n) + m[0, 1] + xs[n]


@wp.func_grad(mixed)
def adj_mixed(v: wp.vec3, n: int, m: wp.mat22, xs: FLOATS, adj_ret: float):
    wp.adjoint[v].x += 2.0 * adj_ret
    wp.adjoint[v][2] = 5.0
    wp.adjoint[m][0, 1] += adj_ret


@wp.func
def sigmoid(x: float):
    return 1.0 / (1.0 + wp.exp(-x))


@wp.func_grad(sigmoid)
def adj_sigmoid(x: float, adj: float):
    # A gradient function may call its own primal (Warp's test does).
    wp.adjoint[x] += adj * sigmoid(x) * (1.0 - sigmoid(x))


@wp.kernel
def many_kernel(a: FLOATS, b: FLOATS):
    i = wp.tid()
    p, q = pair(a[i], 2.0)
    b[i] = p + q + mixed(wp.vec3(a[i]), i, wp.mat22(), a) + sigmoid(a[i])


# --- IR shape -------------------------------------------------------------------------


def test_kept_call_and_grad_functions_in_ir():
    module = sqrt_kernel.build_module()
    run_pipeline(module, KEEP)
    text = print_module(module)
    assert print_module(parse_module(text)) == text
    primal = _func(module, "safe_sqrt")
    grad = _func(module, "adj_safe_sqrt")
    replay = _func(module, "replay_safe_sqrt")
    assert primal.attrs["custom_grad"] == grad.attrs["sym_name"]
    assert primal.attrs["custom_replay"] == replay.attrs["sym_name"]
    kernel = module.funcs[0]
    calls = [op.attrs["callee"] for op in kernel.walk() if op.name == "func.call"]
    assert calls == [primal.attrs["sym_name"]]
    assert re.search(r"func\.func @adj_safe_sqrt_\w+\(%x: f32, %adj_ret: f32\) -> \(f32\)", text)
    assert grad.attrs["kind"] == replay.attrs["kind"] == "func"


def test_default_inline_leaves_no_trace():
    module = sqrt_kernel.build_module()
    run_pipeline(module, "inline,fold,dce")
    assert [f.attrs["kind"] for f in module.funcs] == ["kernel"]
    assert not any(op.name == "func.call" for op in module.funcs[0].walk())


def test_signatures_of_grad_functions():
    module = many_kernel.build_module()
    verify_module(module)
    run_pipeline(module, KEEP)
    text = print_module(module)
    assert print_module(parse_module(text)) == text
    assert re.search(r"@adj_pair_\w+\(%x: f32, %y: f32, %adj_ret0: f32, %adj_ret1: f32\) "
                     r"-> \(f32, f32\)", text)  # fmt: skip
    # Ints get a zero adjoint; an array (no zero) comes back unchanged.
    assert re.search(r"@adj_mixed_\w+\(.*\) -> \(vec<3, f32>, i32, mat<2, 2, f32>, "
                     r"array<f32, 1>\)", text)  # fmt: skip
    kernel = module.funcs[0]
    calls = sorted(op.attrs["callee"].rsplit("_", 1)[0] for op in kernel.walk()
                   if op.name == "func.call")  # fmt: skip
    assert calls == ["mixed", "pair", "sigmoid"]


def test_grad_function_values():
    module = many_kernel.build_module()
    run_pipeline(module, KEEP)
    f32 = np.float32
    # A loop, then an early return that skips the assignment to wp.adjoint[y].
    assert _run_func(module, "adj_pair", f32(1), f32(2), f32(0.5), f32(3)) == [1.5, 6.0]
    assert _run_func(module, "adj_pair", f32(1), f32(-2), f32(0.5), f32(3)) == [1.5, 0.0]
    xs = np.zeros(4, np.float32)
    v, n, m, arr = _run_func(module, "adj_mixed", np.ones(3, f32), np.int32(1),
                             np.ones((2, 2), f32), xs, f32(4))  # fmt: skip
    np.testing.assert_array_equal(v, [8, 0, 5])
    assert n == 0
    np.testing.assert_array_equal(m, [[0, 4], [0, 0]])
    assert arr is xs
    s = 1 / (1 + np.exp(-0.3))
    (g,) = _run_func(module, "adj_sigmoid", f32(0.3), f32(2))
    assert g == pytest.approx(2 * s * (1 - s), rel=1e-6)


def test_safe_sqrt_gradient_values():
    module = sqrt_kernel.build_module()
    run_pipeline(module, KEEP)
    assert _run_func(module, "adj_safe_sqrt", np.float32(4), np.float32(2)) == [0.5]
    assert _run_func(module, "adj_safe_sqrt", np.float32(-1), np.float32(2)) == [0.0]


def test_inline_keeps_what_a_kept_call_reaches():
    text = """
func.func @g(%x: f32, %a: f32) -> (f32) {kind = "func"} {
  func.return %a
}
func.func @r(%x: f32) -> (f32) {kind = "func"} {
  func.return %x
}
func.func @f(%x: f32) -> (f32) {custom_grad = "g", custom_replay = "r", kind = "func"} {
  func.return %x
}
func.func @h(%x: f32) -> (f32) {kind = "func"} {
  %y = func.call %x {callee = "f"} : f32
  func.return %y
}
func.func @k(%a: array<f32, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %x = kd.load %a, %i : f32
  %y = func.call %x {callee = "h"} : f32
  kd.store %y, %a, %i
  func.return
}
"""
    kept = parse_module(text)
    run_pipeline(kept, "inline{keep_custom_grad=true}")
    assert sorted(f.attrs["sym_name"] for f in kept.funcs) == ["f", "g", "k", "r"]
    calls = [op.attrs["callee"] for op in kept.get_func("k").walk() if op.name == "func.call"]
    assert calls == ["f"]
    inlined = parse_module(text)
    run_pipeline(inlined, "inline")
    assert [f.attrs["sym_name"] for f in inlined.funcs] == ["k"]


# --- errors ---------------------------------------------------------------------------


def test_adjoint_in_kernel():
    @wp.kernel
    def k(a: FLOATS):
        i = wp.tid()
        wp.adjoint[a] = a  # <-

    with pytest.raises(KdslSyntaxError) as info:
        k.build_module()
    assert_located(info.value, k.func, "only be used inside a function decorated")


def test_adjoint_in_plain_func():
    @wp.func
    def f(x: float):
        wp.adjoint[x] += 1.0  # <-
        return x

    @wp.kernel
    def k(a: FLOATS):
        i = wp.tid()
        a[i] = f(a[i])

    with pytest.raises(KdslSyntaxError) as info:
        k.build_module()
    assert_located(info.value, f.overloads[0].fn, "@kdsl.func_grad")


def test_adjoint_in_python_scope():
    with pytest.raises(KdslSyntaxError, match="func_grad"):
        wp.adjoint[1.0]


def _grad_error(body_fn, cls):
    """Compile a kernel calling ``prim``, whose gradient is ``body_fn``; give the error."""

    @wp.func
    def prim(x: float, xs: FLOATS):
        return x

    wp.func_grad(prim)(body_fn)

    @wp.kernel
    def k(a: FLOATS):
        i = wp.tid()
        a[i] = prim(a[i], a)

    with pytest.raises(cls) as info:
        k.build_module()
    return info.value


def test_adjoint_of_local_name():
    def g(x: float, xs: FLOATS, adj_ret: float):
        y = x * 2.0
        wp.adjoint[y] += adj_ret  # <-

    err = _grad_error(g, KdslSyntaxError)
    assert_located(err, g, "'y' is not a parameter of prim()")


def test_adjoint_of_adj_ret():
    def g(x: float, xs: FLOATS, adj_ret: float):
        wp.adjoint[adj_ret] += 1.0  # <-

    err = _grad_error(g, KdslSyntaxError)
    assert_located(err, g, "'adj_ret' is an adjoint input")


def test_adjoint_of_array_parameter():
    def g(x: float, xs: FLOATS, adj_ret: float):
        wp.adjoint[xs][0] += adj_ret  # <-

    err = _grad_error(g, KdslSyntaxError)
    assert_located(err, g, "adjoints of arrays")


def test_bare_adjoint_in_grad():
    def g(x: float, xs: FLOATS, adj_ret: float):
        a = wp.adjoint  # <-

    err = _grad_error(g, KdslSyntaxError)
    assert_located(err, g, "must be indexed")


def test_grad_returns_a_value():
    def g(x: float, xs: FLOATS, adj_ret: float):
        return adj_ret  # <-

    err = _grad_error(g, KdslSyntaxError)
    assert_located(err, g, "returns nothing")


def test_adjoint_assigned_wrong_type():
    def g(x: float, xs: FLOATS, adj_ret: float):
        wp.adjoint[x] = wp.vec3()  # <-

    err = _grad_error(g, KdslTypeError)
    assert_located(err, g, "wp.adjoint[x] is a f32")


def test_func_grad_of_python_function():
    def plain(x: float):
        return x

    with pytest.raises(KdslTypeError) as info:

        @wp.func_grad(plain)  # <-
        def g(x: float, adj_ret: float):
            pass

    assert_located(info.value, test_func_grad_of_python_function, "got the Python function")


def test_func_grad_of_kernel():
    with pytest.raises(KdslTypeError) as info:
        wp.func_grad(sqrt_kernel)  # <-
    assert_located(info.value, test_func_grad_of_kernel, "got the kernel")


def test_grad_parameters_do_not_fit():
    with pytest.raises(KdslTypeError) as info:

        @wp.func_grad(safe_sqrt)  # <-
        def g(x: int, adj_ret: float):
            pass

    assert_located(info.value, test_grad_parameters_do_not_fit, "does not fit any overload")


def test_grad_adjoint_count_mismatch():
    @wp.func
    def two(x: float):
        return x, x

    @wp.func_grad(two)  # <-
    def g(x: float, adj_ret: float):
        pass

    @wp.kernel
    def k(a: FLOATS):
        i = wp.tid()
        p, q = two(a[i])
        a[i] = p + q

    with pytest.raises(KdslTypeError) as info:
        k.build_module()
    assert_located(info.value, test_grad_adjoint_count_mismatch, "adj_ret0: f32, adj_ret1: f32")


def test_replay_signature():
    with pytest.raises(KdslTypeError) as info:

        @wp.func_replay(safe_sqrt)  # <-
        def r(x: float, y: float):
            return x

    assert_located(info.value, test_replay_signature, "must have the parameters")


def test_replay_results():
    @wp.func
    def p(x: float):
        return x

    @wp.func_replay(p)  # <-
    def r(x: float):
        return 1

    @wp.kernel
    def k(a: FLOATS):
        i = wp.tid()
        a[i] = p(a[i])

    with pytest.raises(KdslTypeError) as info:
        k.build_module()
    assert_located(info.value, test_replay_results, "must return what p() returns")


# --- end to end (needs the adjoint pass to keep calls and call the gradient) --------------

F64 = wp.array(dtype=wp.float64)


@wp.func
def cube(x: wp.float64):
    return x * x * x


@wp.func_grad(cube)
def adj_cube(x: wp.float64, adj_ret: wp.float64):
    wp.adjoint[x] += wp.float64(3.0) * adj_ret  # deliberately not 3 x^2


@wp.kernel
def cube_kernel(a: F64, b: F64):
    i = wp.tid()
    b[i] = cube(a[i]) * wp.float64(2.0)


@wp.func
def pair64(x: wp.float64, y: wp.float64):
    return x * y, x + y


@wp.func_grad(pair64)
def adj_pair64(x: wp.float64, y: wp.float64, adj_ret0: wp.float64, adj_ret1: wp.float64):
    wp.adjoint[x] += wp.float64(10.0) * adj_ret0 + adj_ret1


@wp.kernel
def pair_kernel(a: F64, p: F64, q: F64):
    i = wp.tid()
    p[i], q[i] = pair64(a[i], wp.float64(2.0))


@wp.func
def ident(x: wp.float64):
    return x


@wp.func_grad(ident)
def adj_ident(x: wp.float64, adj_ret: wp.float64):
    wp.adjoint[x] += adj_ret


@wp.func_replay(ident)
def replay_ident(x: wp.float64):
    return wp.float64(2.0) * x


@wp.kernel
def replay_kernel(a: F64, b: F64):
    i = wp.tid()
    b[i] = ident(a[i]) * a[i]


def _adjoint(kernel, backend, a, outs, weights):
    """Gradient wrt ``a`` of ``sum(w * out)`` for each output array."""
    arr = wp.array(a, dtype=wp.float64)
    out_arrs = [wp.zeros(len(a), dtype=wp.float64) for _ in outs]
    wp.launch(kernel, len(a), [arr, *out_arrs], backend=backend)
    grad = wp.zeros(len(a), dtype=wp.float64)
    adj_outs = [wp.array(w, dtype=wp.float64) for w in weights]
    launch_adjoint(kernel, len(a), [arr, *out_arrs], [grad, *adj_outs], backend=backend)
    return grad.numpy()


A = np.array([0.5, 1.0, 2.0, 3.0])
W0 = np.array([1.0, 0.5, 2.0, 1.5])
W1 = np.array([0.25, 1.0, 3.0, 0.5])


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_custom_gradient_is_used(backend):
    got = _adjoint(cube_kernel, backend, A, [0], [W0])
    np.testing.assert_allclose(got, 6.0 * W0)


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_custom_gradient_of_tuple_results(backend):
    got = _adjoint(pair_kernel, backend, A, [0, 1], [W0, W1])
    np.testing.assert_allclose(got, 10.0 * W0 + W1)


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_replay_function_is_replayed(backend):
    # b = ident(a) * a: the product's adjoint reads the replayed ident(a) = 2a.
    got = _adjoint(replay_kernel, backend, A, [0], [W0])
    np.testing.assert_allclose(got, A * W0 + 2.0 * A * W0)


def test_early_return_of_values_from_before_the_if():
    # The frontend fix gradient functions rely on: a name bound to one outer value on
    # both branches (`if c: return a, b` / `return a, b`) is bound after the if.
    @wp.func
    def f(x: float, y: float):
        a = x
        b = y
        if y < 0.0:
            return a, b
        return a, b

    @wp.kernel
    def k(xs: FLOATS):
        i = wp.tid()
        p, q = f(xs[i], 1.0)
        xs[i] = p + q

    module = k.build_module()
    run_pipeline(module, "inline{keep_custom_grad=true}")
    assert [f.attrs["kind"] for f in module.funcs] == ["kernel"]
