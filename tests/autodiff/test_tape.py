"""kdsl.Tape: recording, backward(loss/grads), zero/reset, record_func, copies, adjoint launches."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError
from kdsl.runtime.tape import LaunchRecord, active_tape

F64 = wp.float64


@wp.kernel
def scale(x: wp.array(dtype=F64), y: wp.array(dtype=F64)):
    i = wp.tid()
    y[i] = 2.0 * x[i]


@wp.kernel
def sin_mul(x: wp.array(dtype=F64), c: wp.array(dtype=F64), y: wp.array(dtype=F64)):
    i = wp.tid()
    y[i] = wp.sin(x[i]) * c[i]


@wp.kernel
def sumsq(y: wp.array(dtype=F64), total: wp.array(dtype=F64)):
    i = wp.tid()
    wp.atomic_add(total, 0, y[i] * y[i])


@wp.kernel
def triple_in_place(x: wp.array(dtype=F64)):
    i = wp.tid()
    x[i] = x[i] * 3.0


@wp.kernel(enable_backward=False)
def scale_no_backward(x: wp.array(dtype=F64), y: wp.array(dtype=F64)):
    i = wp.tid()
    y[i] = 2.0 * x[i]


X0 = np.array([0.5, -1.0, 2.0])


def arr(values, requires_grad=True):
    return wp.array(np.asarray(values, dtype=np.float64), dtype=F64, requires_grad=requires_grad)


def zeros(n=3, requires_grad=True):
    return wp.zeros(n, dtype=F64, requires_grad=requires_grad)


def test_records_launches_while_active():
    x, y, total = arr(X0), zeros(), zeros(1)
    wp.launch(scale, 3, [x], [y])  # no tape active: not recorded anywhere
    tape = wp.Tape()
    with tape as t:
        assert t is tape and active_tape() is tape
        wp.launch(scale, 3, [x], [y])
        wp.launch(sumsq, 3, [y], [total], record_tape=False)
        wp.launch(scale, 3, [x], [y], record_cmd=True)  # a command, not a launch
    assert active_tape() is None
    assert len(tape.launches) == 1
    rec = tape.launches[0]
    assert isinstance(rec, LaunchRecord)
    assert rec.kernel is scale and rec.dim == (3,) and rec.inputs == [x] and rec.outputs == [y]
    assert (
        rec.device == "cpu"
        and rec.metadata["caller"]["func"] == "test_records_launches_while_active"
    )
    kernel, _dim, _max_blocks, inputs, outputs, _device, _block_dim = rec[:7]  # Warp's order
    assert (kernel, inputs, outputs) == (scale, [x], [y])


def test_nested_tapes_innermost_records():
    x, y = arr(X0), zeros()
    outer, inner = wp.Tape(), wp.Tape()
    with outer:
        wp.launch(scale, 3, [x], [y])
        with inner:
            wp.launch(scale, 3, [x], [y])
            wp.launch(scale, 3, [x], [y])
        wp.launch(scale, 3, [x], [y])
    assert len(outer.launches) == 2 and len(inner.launches) == 2


def test_tapes_must_exit_in_order():
    a, b = wp.Tape(), wp.Tape()
    a.__enter__()
    b.__enter__()
    with pytest.raises(KdslError, match="out of order"):
        a.__exit__(None, None, None)
    b.__exit__(None, None, None)
    a.__exit__(None, None, None)
    assert active_tape() is None


def chain(x, c):
    """y = sin(x) c, total = sum y^2, recorded on a tape."""
    y, total = zeros(), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(sin_mul, 3, [x, c], [y])
        wp.launch(sumsq, 3, [y], [total])
    return tape, y, total


@pytest.mark.parametrize("backend", ["cpu", "interp"])
def test_backward_loss_matches_analytic(backend):
    c0 = np.array([1.5, 0.25, -2.0])
    x, c, y, total = arr(X0), arr(c0), zeros(), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(sin_mul, 3, [x, c], [y], backend=backend)
        wp.launch(sumsq, 3, [y], [total], backend=backend)
    assert tape.launches[0].backend == backend
    tape.backward(loss=total)
    y0 = np.sin(X0) * c0
    np.testing.assert_allclose(x.grad.numpy(), 2 * y0 * np.cos(X0) * c0, rtol=1e-12)
    np.testing.assert_allclose(c.grad.numpy(), 2 * y0 * np.sin(X0), rtol=1e-12)
    assert tape.gradients[x] is x.grad and tape.gradients[c] is c.grad
    assert total.grad.numpy()[0] == 1.0 and tape.loss is total


def test_backward_with_grads_dict():
    x = arr(X0)
    y = zeros(requires_grad=False)  # no gradient: the given one becomes its .grad
    tape = wp.Tape()
    with tape:
        wp.launch(scale, 3, [x], [y])
    g = arr([1.0, 10.0, 100.0], requires_grad=False)
    tape.backward(grads={y: g})
    assert y.grad is g
    np.testing.assert_array_equal(x.grad.numpy(), [2.0, 20.0, 200.0])
    # An array that has a gradient gets the incoming one copied in.
    y2 = zeros()
    with tape:
        wp.launch(scale, 3, [x], [y2])
    tape.zero()
    tape.backward(grads={y2: arr([1.0, 1.0, 1.0], requires_grad=False)})
    assert y2.grad is not g
    np.testing.assert_array_equal(x.grad.numpy(), [2.0, 2.0, 2.0])  # y was zeroed by zero()


def test_arrays_without_gradients_get_none():
    x = arr(X0, requires_grad=False)
    c, y, total = arr([1.0, 1.0, 1.0]), zeros(), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(sin_mul, 3, [x, c], [y])
        wp.launch(sumsq, 3, [y], [total])
    tape.backward(loss=total)
    assert x.grad is None and x not in tape.gradients
    np.testing.assert_allclose(c.grad.numpy(), 2 * np.sin(X0) ** 2, rtol=1e-12)


def test_backward_twice_accumulates():
    x, total = arr(X0), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(sumsq, 3, [x], [total])
    tape.backward(loss=total)
    tape.backward(loss=total)
    np.testing.assert_allclose(x.grad.numpy(), 2 * (2 * X0))  # two passes of 2x
    assert total.grad.numpy()[0] == 1.0  # the seed is set, not accumulated


def test_backward_twice_through_a_chain_matches_warp():
    x, y, total = arr(X0), zeros(), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(scale, 3, [x], [y])
        wp.launch(sumsq, 3, [y], [total])
    tape.backward(loss=total)
    tape.backward(loss=total)
    np.testing.assert_allclose(x.grad.numpy(), 2 * (8 * X0))


def test_array_read_and_written_in_one_launch():
    x, total = arr(X0), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(triple_in_place, 3, [x], [])
        wp.launch(sumsq, 3, [x], [total])
    np.testing.assert_allclose(x.numpy(), 3 * X0)
    tape.backward(loss=total)
    np.testing.assert_allclose(x.grad.numpy(), 18 * X0)  # d/dx0 of sum (3 x0)^2


def test_same_array_as_input_and_output():
    x, total = arr(X0), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(scale, 3, [x], [x])
        wp.launch(sumsq, 3, [x], [total])
    tape.backward(loss=total)
    np.testing.assert_allclose(x.grad.numpy(), 8 * X0)


def test_zero_and_reset():
    x, c = arr(X0), arr([1.0, 2.0, 3.0])
    tape, y, total = chain(x, c)
    y.retain_grad = True  # else the store into y consumes its gradient, as in Warp
    tape.backward(loss=total)
    assert np.any(x.grad.numpy() != 0) and np.any(y.grad.numpy() != 0)
    tape.zero()
    for a in (x, c, y, total):
        assert not np.any(a.grad.numpy()), a
    assert len(tape.launches) == 2
    tape.backward(loss=total)
    tape.reset()
    assert not np.any(x.grad.numpy()) and tape.launches == [] and tape.gradients == {}
    tape.backward(loss=total)  # nothing recorded: only the seed is set
    assert not np.any(x.grad.numpy())


def test_record_func_runs_in_reverse_order():
    """A NumPy step y = 3 x between two launches, differentiated by record_func."""
    x0 = arr(X0)
    x, y, total = zeros(), zeros(), zeros(1)
    tape = wp.Tape()
    order = []
    with tape:
        wp.launch(scale, 3, [x0], [x])

        def backward():
            order.append("func")
            x.grad.assign(x.grad.numpy() + 3.0 * y.grad.numpy())

        y.assign(3.0 * x.numpy())
        tape.record_func(backward, [x, y])
        wp.launch(sumsq, 3, [y], [total])
    tape.record_func(lambda: order.append("last"), [])
    tape.backward(loss=total)
    assert order == ["last", "func"]
    np.testing.assert_allclose(x0.grad.numpy(), 2 * 36 * X0)  # total = sum (6 x0)^2


def test_record_func_checks_arguments():
    tape = wp.Tape()
    with pytest.raises(KdslError, match="requires_grad=True"):
        tape.record_func(lambda: None, [zeros(requires_grad=False)])
    with pytest.raises(KdslError, match="callable"):
        tape.record_func(None, [])


def test_loss_errors():
    x, y, total = arr(X0), zeros(), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(scale, 3, [x], [y])
    with pytest.raises(KdslError, match="one-element"):
        tape.backward(loss=y)
    with pytest.raises(KdslError, match="requires_grad=True"):
        tape.backward(loss=zeros(1, requires_grad=False))
    with pytest.raises(KdslError, match="kdsl array"):
        tape.backward(loss=np.zeros(1))
    with pytest.raises(KdslError, match="maps kdsl arrays"):
        tape.backward(grads={y: np.ones(3)})
    tape.backward(loss=total)  # total was not recorded: nothing flows, but no error
    assert not np.any(x.grad.numpy())


def test_enable_backward_false_is_an_error_on_backward():
    x, y, total = arr(X0), zeros(), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(scale_no_backward, 3, [x], [y])
        wp.launch(sumsq, 3, [y], [total])
    with pytest.raises(KdslError, match="enable_backward=False") as e:
        tape.backward(loss=total)
    assert "scale_no_backward" in str(e.value) and "test_tape.py" in str(e.value)
    # Without gradients on its arrays the launch has nothing to differentiate: skipped.
    x2, y2 = arr(X0, requires_grad=False), zeros(requires_grad=False)
    with wp.Tape() as quiet:
        wp.launch(scale_no_backward, 3, [x2], [y2])
    quiet.backward()


def test_copy_on_a_tape_propagates_gradients():
    x, y, z, total = arr(X0), zeros(), zeros(), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.launch(scale, 3, [x], [y])
        wp.copy(z, y)
        wp.launch(sumsq, 3, [z], [total])
    assert len(tape.launches) == 3 and callable(tape.launches[1])
    tape.backward(loss=total)
    np.testing.assert_allclose(x.grad.numpy(), 8 * X0)
    assert not np.any(z.grad.numpy())  # z's values were overwritten: its gradient consumed


def test_copy_window_assign_and_clone():
    x = arr([1.0, 2.0, 3.0, 4.0])
    y, total = zeros(2), zeros(1)
    tape = wp.Tape()
    with tape:
        wp.copy(y, x, dest_offset=0, src_offset=1, count=2)  # y = x[1:3]
        w = wp.clone(y)  # requires_grad follows y: recorded too
        v = zeros(2)
        v.assign(w)
        wp.launch(sumsq, 2, [v], [total])
    assert len(tape.launches) == 4
    tape.backward(loss=total)
    np.testing.assert_allclose(x.grad.numpy(), [0.0, 4.0, 6.0, 0.0])
    # Copies between arrays without gradients are not recorded.
    with wp.Tape() as t2:
        wp.copy(zeros(2, requires_grad=False), x, count=2)
        zeros(4, requires_grad=False).assign(x)
    assert t2.launches == []


def test_adjoint_launch():
    x, c, y = arr(X0, requires_grad=False), arr([1.0, 2.0, 3.0], requires_grad=False), zeros()
    wp.launch(sin_mul, 3, [x, c], [y])
    adj_x, adj_y = zeros(requires_grad=False), arr([1.0, 1.0, 1.0], requires_grad=False)
    adj_x.fill_(1.0)  # adjoint launches add into the input gradients
    with wp.Tape() as tape:
        wp.launch(
            sin_mul, 3, [x, c], [y], adj_inputs=[adj_x, None], adj_outputs=[adj_y], adjoint=True
        )
    assert tape.launches == []  # adjoint launches are never recorded
    np.testing.assert_allclose(adj_x.numpy(), 1.0 + np.cos(X0) * [1.0, 2.0, 3.0], rtol=1e-12)


def test_adjoint_launch_errors():
    x, y = arr(X0), zeros()
    with pytest.raises(KdslLaunchError, match="1 adj_inputs for 2 inputs"):
        wp.launch(sin_mul, 3, [x, x], [y], adj_inputs=[x.grad], adjoint=True)
    with pytest.raises(KdslLaunchError, match="record_cmd"):
        wp.launch(scale, 3, [x], [y], adjoint=True, record_cmd=True)
    with pytest.raises(KdslError, match="enable_backward=False"):
        wp.launch(scale_no_backward, 3, [x], [y], [x.grad], [y.grad], adjoint=True)


def test_a_store_consumes_the_gradient_unless_retained():
    x, c = arr(X0), arr([1.0, 2.0, 3.0])
    tape, y, total = chain(x, c)
    tape.backward(loss=total)
    assert not np.any(y.grad.numpy())  # consumed by the store y[i] = ...
    x2 = arr(X0)
    tape2, y2, total2 = chain(x2, c)
    y2.retain_grad = True
    tape2.backward(loss=total2)
    np.testing.assert_allclose(y2.grad.numpy(), 2 * np.sin(X0) * np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(x.grad.numpy(), x2.grad.numpy())


@wp.struct
class _Body:
    rot: wp.array(dtype=F64)
    out: wp.array(dtype=F64)


@wp.struct
class _Scene:
    body: _Body


@wp.kernel
def _square_rot(s: _Scene):
    i = wp.tid()
    s.body.out[i] = s.body.rot[i] * s.body.rot[i]


@pytest.mark.parametrize("backend", ["cpu", "interp"])
def test_struct_array_fields_gradients_are_on_the_tape(backend):
    # Warp's optim/example_diffray reads tape.gradients[struct.field]; a launch whose
    # only gradients live in struct fields is still replayed.
    scene = _Scene()
    scene.body = _Body()
    scene.body.rot, scene.body.out = arr(X0), zeros()
    tape = wp.Tape()
    with tape:
        wp.launch(_square_rot, 3, [scene], backend=backend)
    assert tape.gradients[scene.body.rot] is scene.body.rot.grad
    tape.backward(grads={scene.body.out: wp.ones(3, dtype=F64)})
    np.testing.assert_allclose(scene.body.rot.grad.numpy(), 2 * X0)
    tape.zero()
    assert not scene.body.rot.grad.numpy().any()
