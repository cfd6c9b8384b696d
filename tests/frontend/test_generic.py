"""Generic code (Warp's): ``Any`` parameters, ``kdsl.overload``, ``@func`` defaults and
keywords, ``static()`` yielding a function, and Warp's overload resolution."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslLaunchError, KdslSyntaxError, KdslTypeError
from kdsl.ir import types as T

BACKENDS = [
    "interp",
    "cpu",
    pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")),
]


@pytest.fixture(autouse=True)
def _device_of_the_backend(request):
    """Arrays and launches of a test run on its backend's device (cuda:0 for cuda)."""
    callspec = getattr(request.node, "callspec", None)
    backend = callspec.params.get("backend") if callspec is not None else None
    with wp.ScopedDevice("cuda:0" if backend == "cuda" else "cpu"):
        yield


@wp.func
def twice(x: Any):
    return x + x


@wp.func
def first(a: wp.array(dtype=Any)):
    return a[0]


@wp.kernel
def add_first(a: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    i = wp.tid()
    out[i] = twice(a[i]) + first(a)


@wp.kernel
def fill(out: wp.array2d[Any], value: Any):
    i, j = wp.tid()
    out[i, j] = value


@wp.func
def scale(x: float, s: float = 2.0, bias: float = 0.0):
    return x * s + bias


@wp.kernel
def defaults(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = scale(a[i]) + scale(a[i], 3.0) + scale(a[i], bias=100.0) + scale(x=a[i], s=0.0)


@wp.func
def kind(x: Any):
    return 2


@wp.func
def kind(x: float):  # noqa: F811  (an overload: concrete ones win over generic ones)
    return 1


@wp.kernel
def kinds(a: wp.array(dtype=float), b: wp.array(dtype=wp.float64), out: wp.array(dtype=int)):
    out[0] = kind(a[0])
    out[1] = kind(b[0])
    out[2] = kind(1.5)  # a float literal is a float32: the concrete overload
    out[3] = kind(7)  # an int literal is an int32: the generic one (as in Warp)


@wp.func
def add_one(x: float):
    return x + 1.0


@wp.func
def negate(x: float):
    return -x


OPS = [add_one, negate]
BY_NAME = {"add": add_one, "neg": negate}


def make_apply(op):
    @wp.kernel
    def apply(a: wp.array(dtype=float), out: wp.array(dtype=float)):
        i = wp.tid()
        out[i] = wp.static(op)(a[i]) + wp.static(OPS[1])(a[i]) * wp.static(BY_NAME["add"])(0.0)

    return apply


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    "dtype, data, want",
    [
        (wp.float32, [0.0, 1.5, 2.0], [0.0, 3.0, 4.0]),
        (wp.int32, [3, 1, 2], [9, 5, 7]),
        (wp.float64, [1.0, 2.0, 3.0], [3.0, 5.0, 7.0]),
    ],
)
def test_generic_kernel_instantiates_per_dtype(backend, dtype, data, want):
    a = wp.array(np.array(data), dtype=dtype)
    out = wp.zeros(3, dtype=dtype)
    wp.launch(add_first, 3, [a, out], backend=backend)
    np.testing.assert_allclose(out.numpy(), want)
    inst = add_first.instance([a.__kdsl_type__, out.__kdsl_type__])
    assert not inst.is_generic and inst.name == "add_first"


@pytest.mark.parametrize("backend", BACKENDS)
def test_generic_kernel_with_vectors_and_scalars(backend):
    a = wp.array(np.ones((4, 3), np.float32), dtype=wp.vec3)
    out = wp.zeros(4, dtype=wp.vec3)
    wp.launch(add_first, 4, [a, out], backend=backend)
    np.testing.assert_allclose(out.numpy(), 3.0)
    grid = wp.zeros((2, 3), dtype=wp.vec2)
    wp.launch(fill, (2, 3), [grid, wp.vec2(1.0, 2.0)], backend=backend)
    np.testing.assert_allclose(grid.numpy()[1, 2], [1.0, 2.0])
    ints = wp.zeros((2, 2), dtype=int)
    wp.launch(fill, (2, 2), [ints, 5], backend=backend)  # a Python int is an int32
    assert ints.numpy().tolist() == [[5, 5], [5, 5]]
    halves = wp.zeros((1, 2), dtype=wp.float64)
    wp.launch(fill, (1, 2), [halves, np.float64(0.5)], backend=backend)
    assert halves.numpy().tolist() == [[0.5, 0.5]]


def test_instances_are_cached_and_keyed_by_types():
    a = wp.zeros(2, dtype=wp.int64)
    wp.launch(add_first, 2, [a, wp.zeros(2, dtype=wp.int64)], backend="interp")
    before = len(add_first.instances())
    wp.launch(add_first, 2, [a, wp.zeros(2, dtype=wp.int64)], backend="interp")
    assert len(add_first.instances()) == before
    keys = {inst.key for inst in add_first.instances()}
    assert len(keys) == len(add_first.instances())


@pytest.mark.parametrize("backend", BACKENDS)
def test_overload_declares_an_instance(backend):
    @wp.kernel
    def copy(src: wp.array(dtype=Any), dst: wp.array(dtype=Any)):
        i = wp.tid()
        dst[i] = src[i]

    by_list = wp.overload(copy, [wp.array(dtype=wp.float16), wp.array(dtype=wp.float16)])
    by_dict = wp.overload(copy, {"src": wp.array[wp.vec2], "dst": wp.array[wp.vec2]})
    assert by_list.arg_types == [T.ArrayType(T.F16, 1)] * 2
    assert by_dict.arg_types == [T.ArrayType(T.VectorType(2, T.F32), 1)] * 2
    src = wp.array(np.array([[1, 2], [3, 4]], np.float32), dtype=wp.vec2)
    dst = wp.zeros(2, dtype=wp.vec2)
    wp.launch(by_dict, 2, [src, dst], backend=backend)  # the instance launches directly
    np.testing.assert_allclose(dst.numpy(), src.numpy())
    # The generic kernel finds the declared instance for the same types.
    wp.launch(copy, 2, [src, dst], backend=backend)
    assert len(copy.instances()) == 2


@wp.kernel
def cube(x: wp.array(dtype=Any)):
    i = wp.tid()
    x[i] = x[i] * x[i] * x[i]


@wp.overload
def cube(x: wp.array(dtype=wp.int64)): ...  # noqa: F811


def test_overload_decorator_at_module_level():
    generic = next(k for k in wp.get_module(__name__).kernels if k.name == "cube")
    assert [inst.arg_types for inst in generic.instances()] == [[T.ArrayType(T.I64, 1)]]
    x = wp.array(np.array([2], np.int64), dtype=wp.int64)
    wp.launch(generic, 1, [x], backend="interp")
    assert x.numpy().tolist() == [8]


@pytest.mark.parametrize(
    "args, message",
    [
        (lambda: [[wp.array(dtype=float)]], "takes 2 parameters"),
        (lambda: [[float, wp.array(dtype=float)]], "parameter 'src' is array"),
        (lambda: [{"nope": float}], "no parameter 'nope'"),
        (lambda: [{"src": wp.array(dtype=float)}], "'dst' .* needs a concrete type"),
        (lambda: [[wp.array(dtype=float), object()]], "not a concrete kdsl type"),
        (lambda: [3], "list of types or a dict"),
    ],
)
def test_overload_errors(args, message):
    @wp.kernel
    def copy(src: wp.array(dtype=Any), dst: wp.array(dtype=Any)):
        i = wp.tid()
        dst[i] = src[i]

    with pytest.raises(KdslTypeError, match=message):
        wp.overload(copy, *args())


def test_overload_of_a_concrete_kernel_is_refused():
    with pytest.raises(KdslTypeError, match="not generic"):
        wp.overload(defaults, [wp.array(dtype=float), wp.array(dtype=float)])
    with pytest.raises(KdslTypeError, match="no kernel named"):

        @wp.overload
        def not_a_kernel(x: float): ...


@pytest.mark.parametrize("backend", BACKENDS)
def test_launch_errors_for_impossible_inference(backend):
    with pytest.raises(KdslLaunchError, match=r"argument 0 'a'.*array\(dtype=Any, ndim=1\)") as err:
        wp.launch(add_first, 1, [1.0, wp.zeros(1)], backend=backend)
    assert "test_generic.py" in str(err.value)
    with pytest.raises(KdslLaunchError, match=r"ndim=2.*array<f32, 1>"):
        wp.launch(fill, 1, [wp.zeros(3), 1.0], backend=backend)
    with pytest.raises(KdslLaunchError, match="cannot instantiate it for str"):
        wp.launch(fill, 1, [wp.zeros((1, 1)), "x"], backend=backend)
    with pytest.raises(KdslLaunchError, match="takes 2 arguments"):
        wp.launch(fill, 1, [wp.zeros((1, 1))], backend=backend)
    with pytest.raises(KdslTypeError, match="cannot store a f32 into an array of i32"):
        wp.launch(add_first, 1, [wp.zeros(1), wp.zeros(1, dtype=int)], backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_func_defaults_and_keywords(backend):
    a = wp.array(np.array([1.0, 2.0], np.float32))
    out = wp.zeros(2, dtype=float)
    wp.launch(defaults, 2, [a, out], backend=backend)
    # 2x + 3x + (2x + 100) + 0
    np.testing.assert_allclose(out.numpy(), [107.0, 114.0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_concrete_overloads_win_over_generic_ones(backend):
    out = wp.zeros(4, dtype=int)
    a, b = wp.zeros(1, dtype=float), wp.zeros(1, dtype=wp.float64)
    wp.launch(kinds, 1, [a, b, out], backend=backend)
    assert out.numpy().tolist() == [1, 2, 1, 2]


@pytest.mark.parametrize("backend", BACKENDS)
def test_static_yields_a_function(backend):
    a = wp.array(np.array([1.0, 2.0], np.float32))
    out = wp.zeros(2, dtype=float)
    wp.launch(make_apply(add_one), 2, [a, out], backend=backend)
    # op(x) + negate(x) * add_one(0) = (x + 1) - x
    np.testing.assert_allclose(out.numpy(), [1.0, 1.0])
    wp.launch(make_apply(negate), 2, [a, out], backend=backend)
    np.testing.assert_allclose(out.numpy(), [-2.0, -4.0])


def _build_error(fn, kind=KdslTypeError):
    with pytest.raises(kind) as err:
        wp.kernel(fn).build_module()
    assert "test_generic.py" in str(err.value)
    return str(err.value)


def test_call_errors_name_the_call():
    def missing(a: wp.array(dtype=float)):
        a[0] = scale()

    def unknown(a: wp.array(dtype=float)):
        a[0] = scale(1.0, t=2.0)

    def twice_given(a: wp.array(dtype=float)):
        a[0] = scale(1.0, x=2.0)

    def too_many(a: wp.array(dtype=float)):
        a[0] = scale(1.0, 2.0, 3.0, 4.0)

    def generic_array_mismatch(a: wp.array(dtype=float)):
        a[0] = first(a[0])

    assert "missing argument 'x'" in _build_error(missing)
    assert "no parameter 't'" in _build_error(unknown)
    assert "two values for 'x'" in _build_error(twice_given)
    assert "takes 3 arguments, got 4" in _build_error(too_many)
    assert "array(dtype=Any, ndim=1)" in _build_error(generic_array_mismatch)


def test_bad_defaults_and_static_results_are_errors():
    @wp.func
    def bad_default(x: float, s: float = None):  # noqa: RUF013
        return x

    def uses_bad_default(a: wp.array(dtype=float)):
        a[0] = bad_default(1.0)

    def kernel_default(a: wp.array(dtype=float), s: float = 1.0):
        a[0] = s

    def static_python_function(a: wp.array(dtype=float)):
        a[0] = wp.static(len)([1])

    assert "default value of 's' is the Python object 'NoneType'" in _build_error(uses_bad_default)
    assert "cannot have default values" in _build_error(kernel_default, KdslSyntaxError)
    assert "or a @kdsl.func" in _build_error(static_python_function)


@pytest.mark.parametrize("backend", BACKENDS)
def test_generic_kernel_gradients_on_a_tape(backend):
    @wp.kernel
    def square(x: wp.array(dtype=Any), y: wp.array(dtype=Any)):
        i = wp.tid()
        y[i] = x[i] * x[i]

    x = wp.array(np.array([1.0, 3.0], np.float32), requires_grad=True)
    y = wp.zeros(2, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square, 2, [x, y], backend=backend)
    tape.backward(grads={y: wp.array(np.ones(2, np.float32))})
    np.testing.assert_allclose(x.grad.numpy(), [2.0, 6.0])


def test_module_load_compiles_declared_instances():
    def negate_all(x: wp.array(dtype=Any)):
        i = wp.tid()
        x[i] = -x[i]

    # A module of its own: this file's other kernels include deliberately broken ones.
    negate_all.__module__ = "kdsl_test_generic_load"
    generic = wp.kernel(negate_all)
    inst = wp.overload(generic, [wp.array(dtype=wp.float64)])
    module = wp.get_module("kdsl_test_generic_load")
    module.load("cpu")
    assert getattr(inst, "_kdsl_plans", None)  # compiled ahead of the first launch
    module.unload()
    assert not hasattr(inst, "_kdsl_plans")


@wp.func
def twice_float(x: wp.Float):
    return x + x


@wp.func
def bump(x: wp.Int):
    return x + 1


@wp.func
def sq(x: wp.types.Scalar):
    return x * x


@pytest.mark.parametrize("backend", BACKENDS)
def test_warp_generic_scalar_annotations(backend):
    @wp.kernel
    def use(f: wp.array(dtype=float), n: wp.array(dtype=wp.int64), out: wp.array(dtype=float)):
        n[0] = bump(n[0])
        n[1] = sq(n[1])
        out[0] = sq(f[0]) + float(bump(2)) + twice_float(f[0])

    f = wp.array(np.array([3.0], np.float32))
    n = wp.array(np.array([4, 5], np.int64), dtype=wp.int64)
    out = wp.zeros(1, dtype=float)
    wp.launch(use, 1, [f, n, out], backend=backend)
    assert n.numpy().tolist() == [5, 25] and out.numpy().tolist() == [18.0]

    def float_to_int(a: wp.array(dtype=float)):
        a[0] = float(bump(a[0]))

    assert "(Int)" in _build_error(float_to_int)


def test_user_funcs_with_defaults_run_as_python():
    assert scale(2.0) == 4.0 and scale(2.0, bias=1.0) == 5.0 and scale(x=1.0, s=3.0) == 3.0
    with pytest.raises(TypeError, match="no overload taking 0 arguments"):
        scale()
