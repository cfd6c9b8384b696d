"""kdsl.launch: argument checks, backend choice, compile caching, record_cmd."""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslLaunchError


def test_saxpy_with_kdsl_arrays(saxpy):
    x = wp.array(np.arange(4), dtype=float)
    y = wp.ones(4, dtype=float)
    wp.launch(saxpy, dim=4, inputs=[x, y, 2.0])
    np.testing.assert_array_equal(y.numpy(), [1, 3, 5, 7])


def test_numpy_arrays_and_outputs_are_accepted(saxpy):
    x = np.arange(3, dtype=np.float32)
    y = np.zeros(3, np.float32)
    wp.launch(saxpy, dim=3, inputs=[x], outputs=[y, 3])  # int for an f32 parameter is fine
    np.testing.assert_array_equal(y, [0, 3, 6])


def test_compiles_once_per_backend(saxpy):
    x, y = wp.zeros(2), wp.zeros(2)
    for _ in range(3):
        wp.launch(saxpy, dim=2, inputs=[x, y, 1.0])
    assert saxpy.builds == 1
    other = "interp" if wp.default_backend_for("cpu") != "interp" else "cpu"
    for _ in range(2):
        wp.launch(saxpy, dim=2, inputs=[x, y, 1.0], backend=other)
    assert saxpy.builds == 2


def test_vector_parameters_and_arrays(mixed):
    p = wp.zeros(2, dtype=wp.vec3)
    m = wp.zeros((2, 2), dtype=float)
    wp.launch(mixed, dim=2, inputs=[p, 5, wp.vec3(1, 2, 3), m])
    wp.launch(mixed, dim=2, inputs=[p, 5, (1.0, 1.0, 1.0), m])
    wp.launch(mixed, dim=2, inputs=[p.numpy(), 5, np.ones(3, np.float32), m])
    np.testing.assert_array_equal(p.numpy(), [[3, 4, 5]] * 2)


def test_multi_dim_launch(grid):
    out = wp.zeros((2, 3), dtype=int)
    wp.launch(grid, dim=(2, 3), inputs=[out])
    np.testing.assert_array_equal(out.numpy(), np.arange(6).reshape(2, 3))


def err(kernel, dim, inputs, match, **kw):
    with pytest.raises(KdslLaunchError, match=match) as info:
        wp.launch(kernel, dim=dim, inputs=inputs, **kw)
    return str(info.value)


def test_wrong_argument_count(saxpy):
    msg = err(saxpy, 2, [wp.zeros(2)], r"kernel 'saxpy' takes 3 arguments \(x, y, a\) but 1 were")
    assert "1 inputs, 0 outputs" in msg


def test_wrong_array_dtype(saxpy):
    err(
        saxpy,
        2,
        [wp.zeros(2, dtype=wp.float64), wp.zeros(2), 1.0],
        r"kernel 'saxpy', argument 0 'x': expected an array of f32, got an array of f64",
    )


def test_float64_numpy_array_is_not_narrowed(saxpy):
    err(saxpy, 2, [np.zeros(2), wp.zeros(2), 1.0], r"argument 0 'x'.*got a NumPy float64 array")


def test_wrong_ndim(saxpy):
    err(saxpy, 2, [wp.zeros((2, 2)), wp.zeros(2), 1.0], "expected a 1-d array, got a 2-d array")
    err(saxpy, 2, [np.zeros((2, 2), np.float32), wp.zeros(2), 1.0], "got shape \\(2, 2\\)")


def test_wrong_device_string(saxpy):
    with pytest.raises(KdslError, match="unknown device 'gpu7'"):
        wp.launch(saxpy, dim=2, inputs=[wp.zeros(2), wp.zeros(2), 1.0], device="gpu7")
    with pytest.raises(KdslError, match="'cuda:3' is not available"):
        wp.launch(saxpy, dim=2, inputs=[wp.zeros(2), wp.zeros(2), 1.0], device="cuda:3")


def test_float_to_int_parameter(mixed):
    p, m = wp.zeros(1, dtype=wp.vec3), wp.zeros((1, 1))
    err(mixed, 1, [p, 2.5, (0, 0, 0), m], r"argument 1 'n': expected i32, got float 2.5")
    err(mixed, 1, [p, np.int64(2), (0, 0, 0), m], "expected i32, got NumPy int64")
    err(mixed, 1, [p, 2**40, (0, 0, 0), m], "does not fit in i32")


def test_numpy_float64_scalar_to_f32_parameter(saxpy):
    err(saxpy, 2, [wp.zeros(2), wp.zeros(2), np.float64(1)], "expected f32, got NumPy float64")


def test_array_to_scalar_parameter(saxpy):
    err(
        saxpy,
        2,
        [wp.zeros(2), wp.zeros(2), wp.zeros(2)],
        r"argument 2 'a': expected f32, got array of f32",
    )


def test_scalar_to_array_parameter(saxpy):
    err(saxpy, 2, [1.0, wp.zeros(2), 1.0], r"argument 0 'x': expected an array of f32, got float")


def test_vector_length_mismatch(mixed):
    p, m = wp.zeros(1, dtype=wp.vec3), wp.zeros((1, 1))
    err(
        mixed,
        1,
        [p, 1, (1.0, 2.0), m],
        r"argument 2 'v': expected vec<3, f32> \(3 components\), got 2",
    )
    err(mixed, 1, [p, 1, wp.vec4(), m], "expected vec<3, f32>")
    err(mixed, 1, [p, 1, wp.vec3d(), m], "expected vec<3, f32>, got vec<3, f64>")
    err(mixed, 1, [np.zeros((1, 4), np.float32), 1, (0, 0, 0), m], "got shape \\(1, 4\\)")


def test_tid_ndim_mismatch(grid):
    err(
        grid,
        6,
        [wp.zeros((2, 3), dtype=int)],
        r"kernel 'grid' uses a 2-d thread index \(i, j = tid\(\)\) but was launched with 1-d dim=6",
    )


def test_bad_dims(saxpy):
    args = [wp.zeros(2), wp.zeros(2), 1.0]
    err(saxpy, (1, 2, 3, 4, 5), args, "1 to 4")
    err(saxpy, -1, args, "non-negative")
    err(saxpy, 2.0, args, "dim must be an int")


def test_adjoint_launch(saxpy):
    # y = a x + y: the adjoint adds a * adj_y into adj_x (tests/autodiff covers the rest).
    adj_x = wp.zeros(2)
    wp.launch(
        saxpy, dim=2, inputs=[wp.ones(2), wp.ones(2), 3.0], adj_inputs=[adj_x, wp.ones(2), 0.0],
        adjoint=True,
    )  # fmt: skip
    assert adj_x.numpy().tolist() == [3.0, 3.0]


def test_unknown_backend(saxpy):
    with pytest.raises(KdslError, match="no kdsl backend is named 'tpu'"):
        wp.launch(saxpy, dim=1, inputs=[wp.zeros(1), wp.zeros(1), 1.0], backend="tpu")


def test_default_backend_for_cpu_prefers_cpu_backend(monkeypatch):
    from kdsl.runtime import launch as launch_mod

    monkeypatch.setattr(launch_mod, "is_registered", lambda name: name == "cpu")
    assert wp.default_backend_for("cpu") == "cpu"
    monkeypatch.setattr(launch_mod, "is_registered", lambda name: False)
    assert wp.default_backend_for("cpu") == "interp"


def test_record_cmd_relaunch(saxpy):
    x, y = wp.array([1.0, 2.0, 3.0], dtype=float), wp.zeros(3)
    cmd = wp.launch(saxpy, dim=3, inputs=[x, y, 1.0], record_cmd=True)
    assert isinstance(cmd, wp.Launch)
    np.testing.assert_array_equal(y.numpy(), 0)  # recorded, not run
    cmd.launch()
    np.testing.assert_array_equal(y.numpy(), [1, 2, 3])
    cmd.set_param_at_index(2, 10.0)
    cmd.launch()
    np.testing.assert_array_equal(y.numpy(), [11, 22, 33])
    y2 = wp.zeros(3)
    cmd.set_param_by_name("y", y2)
    cmd.set_dim(2)
    cmd.launch()
    np.testing.assert_array_equal(y2.numpy(), [10, 20, 0])
    with pytest.raises(KdslLaunchError, match="argument 2 'a': expected f32"):
        cmd.set_param_at_index(2, "x")
    with pytest.raises(KdslLaunchError, match="no index 9"):
        cmd.set_param_at_index(9, 1.0)


def test_a_cpu_backend_that_fails_to_load_falls_back_to_interp_loudly(monkeypatch, saxpy):
    from kdsl.backends.registry import BackendRegistryError
    from kdsl.runtime import launch as launch_mod

    real = launch_mod.get_backend

    def broken_cpu(name):
        if name == "cpu":
            raise BackendRegistryError("kdsl backend 'cpu' failed to load: ImportError: boom")
        return real(name)

    monkeypatch.setattr(launch_mod, "get_backend", broken_cpu)
    monkeypatch.setattr(launch_mod, "_warned_fallback", False)
    monkeypatch.setattr(launch_mod, "default_backend_for", lambda device: "cpu")
    y = wp.zeros(2)
    with pytest.warns(RuntimeWarning, match="run on the interp backend.*boom"):
        wp.launch(saxpy, dim=2, inputs=[wp.array([1.0, 2.0], dtype=float), y, 2.0])
    np.testing.assert_array_equal(y.numpy(), [2.0, 4.0])
