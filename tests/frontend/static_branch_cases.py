"""Kernel factories whose branches are picked by ``wp.static`` (and other compile-time
conditions); the branch not taken holds code that does not type-check for ``float32``.

Each ``factory(wp, flag, kopts)`` takes the module (``kdsl`` or ``warp``, for the
side-by-side test), a Python bool the branches test and the kernel decorator's options
(Warp needs ``module="unique"`` so that one failing kernel does not stop the others).
Every kernel has the signature ``k(a: array(dtype=float32), n: array(dtype=int))``;
the tests launch it on two threads with ``a = 1.0`` and ``n = 3``.
"""

# ruff: noqa: UP018, RUF046, B007

import numpy as np


def _kernel_calling(wp, f, kopts):
    """The kernel ``a[i] = f(a[i], n[i])`` for a ``@func`` ``f``."""

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=wp.float32), n: wp.array(dtype=int)):
        i = wp.tid()
        a[i] = f(a[i], n[i])

    return k


def top_if(wp, flag, kopts):
    """if/elif/else at a kernel's top level: a ``wp.types`` check, a closure constant."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        v = a[i]
        if wp.static(dtype == wp.float64):
            v = v + wp.float64(1.0)
        elif wp.static(not flag):
            v = v + wp.float64(2.0)  # <-
        else:
            v = v + dtype(3.0)
        a[i] = v

    return k


def not_static(wp, flag, kdopts):
    """``not wp.static(c)``: kdsl folds it (Warp 1.19 does not, see docs/language.md)."""
    dtype = wp.float32

    @wp.kernel(**kdopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        v = a[i]
        if not wp.static(flag):
            v = v + wp.float64(1.0)  # <-
        a[i] = v

    return k


def for_body(wp, flag, kopts):
    """``if wp.static(False)`` in a dynamic for loop."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        v = a[i]
        for j in range(n[i]):
            if wp.static(False):
                v = v + wp.float64(1.0)
            else:
                v = v + dtype(1.0)
        a[i] = v

    return k


def while_body(wp, flag, kopts):
    """if/elif in a while loop's body, without an else."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        v = a[i]
        j = int(0)
        while j < n[i]:
            if wp.static(dtype == wp.float64):
                v = v + wp.float64(1.0)
            elif wp.static(flag):
                v = v + dtype(2.0)
            j += 1
        a[i] = v

    return k


def while_condition(wp, flag, kopts):
    """A nested conditional expression as a while loop's whole condition."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        j = int(0)
        while (
            (a[i] < wp.float64(9.0))
            if wp.static(dtype == wp.float64)
            else ((a[i] < dtype(9.0)) if wp.static(flag) else (j < 2))
        ):
            a[i] = a[i] + dtype(1.0)
            j += 1
        n[i] = j

    return k


def while_condition_operand(wp, flag, kopts):
    """A nested conditional expression as an operand of a while loop's condition."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        j = int(0)
        while j < (
            wp.float64(1.0)
            if wp.static(dtype == wp.float64)
            else (n[i] if wp.static(flag) else a[i] + wp.float64(1.0))  # <-
        ):
            j += 1
        n[i] = j

    return k


def func_loops(wp, flag, kopts):
    """``if wp.static(False)`` in the for and while loops of a ``@func``."""
    dtype = wp.float32

    @wp.func
    def f(x: dtype, m: int):
        y = x
        for j in range(m):
            if wp.static(False):
                y = y + wp.float64(1.0)
            y = y + dtype(1.0)
        j = int(0)
        while j < m:
            if wp.static(False):
                y = y * wp.float64(2.0)
            j += 1
        return y

    return _kernel_calling(wp, f, kopts)


def nested_funcs(wp, flag, kopts):
    """A ``@func`` calling a ``@func``, each picking a branch (and a return) statically."""
    dtype = wp.float32

    @wp.func
    def g(x: dtype):
        if wp.static(dtype == wp.float64):
            return x + wp.float64(1.0)
        return x + dtype(5.0)

    @wp.func
    def f(x: dtype, m: int):
        y = x
        j = int(0)
        while j < m:
            if wp.static(dtype != wp.float64):
                y = g(y)
            else:
                y = y + wp.float64(1.0)
            j += 1
        return y

    return _kernel_calling(wp, f, kopts)


def returns_in_loops(wp, flag, kopts):
    """Returns of other types in statically dead branches of a ``@func``'s loops."""
    dtype = wp.float32

    @wp.func
    def f(x: dtype, m: int):
        j = int(0)
        while j < m:
            if wp.static(dtype == wp.float64):
                return x + wp.float64(1.0)
            j += 1
        for q in range(m):
            if wp.static(not flag):
                return x, x, wp.float64(1.0)
        return x + dtype(1.0)

    return _kernel_calling(wp, f, kopts)


def exits_in_loop(wp, flag, kopts):
    """``break`` and ``continue`` in statically picked branches of a while loop."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        j = int(0)
        while j < n[i]:
            j += 1
            if wp.static(dtype == wp.float64):
                a[i] = a[i] + wp.float64(1.0)
                break
            elif wp.static(not flag):
                continue
            a[i] = a[i] + dtype(1.0)
        n[i] = j

    return k


def types_queries(wp, flag, kopts):
    """Warp's ``wp.types`` queries as static conditions in a while loop."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        j = int(0)
        while j < n[i]:
            if wp.static(wp.types.types_equal(dtype, wp.float64)):
                a[i] = a[i] + wp.float64(1.0)
            elif wp.static(wp.types.type_is_float(dtype) and flag):
                a[i] = a[i] + dtype(2.0)
            elif wp.static(wp.types.type_is_int(dtype) or wp.types.type_size_in_bytes(dtype) != 4):
                a[i] = a[i] + wp.float64(3.0)
            j += 1

    return k


def conditional_expression(wp, flag, kopts):
    """Nested conditional expressions at a kernel's top level."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        a[i] = (
            (a[i] + wp.float64(1.0))
            if wp.static(dtype == wp.float64)
            else ((a[i] * dtype(2.0)) if wp.static(flag) else a[i] + wp.float64(7.0))  # <-
        )

    return k


def closure_condition(wp, flag, kopts):
    """A closure constant tested without ``wp.static`` (Warp folds it too)."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        j = int(0)
        while j < n[i]:
            if flag:
                a[i] = a[i] + dtype(1.0)
            else:
                a[i] = a[i] + wp.float64(1.0)
            j += 1

    return k


def static_and_or(wp, flag, kopts):
    """``and``/``or`` with a static operand: the other operand only where it decides."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        j = int(0)
        while j < n[i] and wp.static(flag):
            a[i] = a[i] + dtype(1.0)
            j += 1
        if wp.static(flag) and a[i] > dtype(0.0):
            a[i] = a[i] + dtype(1.0)
        if wp.static(flag) or a[i] > dtype(0.0):
            a[i] = a[i] + dtype(1.0)
        n[i] = j

    return k


def dead_code_garbage(wp, flag, kopts):
    """The dead branch holds code that could never compile: an undefined name, a
    string, a slice, a variable changing type, a builtin given the wrong type."""
    dtype = wp.float32

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        v = a[i]
        j = int(0)
        while j < n[i]:
            if wp.static(flag):
                v = v + dtype(1.0)
            else:
                v = no_such_name(a[i]).zz + "text"  # noqa: F821
                v = a[i][0:2]
                v = wp.vec3(1.0, 2.0, 3.0)
                v = wp.normalize(v) + wp.float64(1.0)[3]
            j += 1
        a[i] = v

    return k


def typed_constant(wp, flag, kopts):
    """Typed compile-time conditions: in kdsl's Python scope ``wp.float64(0.5) > 0`` is a
    NumPy bool (Warp's gives a Python bool), and a closure may hold ``np.bool_``."""
    dtype = wp.float32
    c = np.bool_(flag)

    @wp.kernel(**kopts)
    def k(a: wp.array(dtype=dtype), n: wp.array(dtype=int)):
        i = wp.tid()
        if wp.static(wp.float64(0.5) > wp.float64(0.0)):
            a[i] = a[i] + dtype(1.0)
        else:
            a[i] = a[i] + wp.float64(1.0)
        if c:
            a[i] = a[i] + dtype(1.0)
        else:
            a[i] = a[i] + wp.float64(1.0)
        if not c:
            a[i] = a[i] + wp.float64(1.0)
        n[i] = 1 if c else wp.float64(1.0)

    return k


#: (factory, flag) -> Warp 1.19's (a[0], n[0]) on the cpu, for the runs that compile.
RESULTS = {
    (top_if, True): (4.0, 3),
    (for_body, True): (4.0, 3),
    (for_body, False): (4.0, 3),
    (while_body, True): (7.0, 3),
    (while_body, False): (1.0, 3),
    (while_condition, True): (9.0, 8),
    (while_condition, False): (3.0, 2),
    (while_condition_operand, True): (1.0, 3),
    (func_loops, True): (4.0, 3),
    (func_loops, False): (4.0, 3),
    (nested_funcs, True): (16.0, 3),
    (returns_in_loops, True): (2.0, 3),
    (exits_in_loop, True): (4.0, 3),
    (exits_in_loop, False): (1.0, 3),
    (types_queries, True): (7.0, 3),
    (types_queries, False): (1.0, 3),
    (conditional_expression, True): (2.0, 3),
    (closure_condition, True): (4.0, 3),
    (static_and_or, True): (6.0, 3),
    (static_and_or, False): (2.0, 0),
    (dead_code_garbage, True): (4.0, 3),
}

#: Runs kdsl compiles where Warp 1.19 does not (see docs/language.md): their results.
KDSL_ONLY = {
    (not_static, True): (1.0, 3),
    (typed_constant, True): (3.0, 1),
}

#: (factory, flag) whose live branch holds the type error, at the line marked ``# <-``.
LIVE_ERRORS = {
    (top_if, False): "cannot add f32 and f64",
    (not_static, False): "cannot add f32 and f64",
    (while_condition_operand, False): "cannot add f32 and f64",
    (conditional_expression, False): "cannot add f32 and f64",
}
