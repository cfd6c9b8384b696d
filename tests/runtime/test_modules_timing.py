"""Warp's module, cache, timing, logging, device and mempool API (issue 14, items 6 and 9)."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest

import kdsl as wp
from kdsl import config
from kdsl.compiler import cache as kcache
from kdsl.runtime import modules
from kdsl.runtime.launch import launch_plan

BACKENDS = ["interp", "cpu"]
cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


def _scale(a: wp.array(dtype=float), s: float):
    i = wp.tid()
    a[i] = a[i] * s


def _oob(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i + 100] = 1.0


def kernel_in(module: str, fn, **options):
    """A kernel of ``fn`` that belongs to the Python module ``module``."""
    clone = type(fn)(fn.__code__, fn.__globals__, fn.__name__)
    clone.__module__ = module
    clone.__annotations__ = dict(fn.__annotations__)
    clone.__qualname__ = fn.__qualname__
    return wp.kernel(clone, **options) if options else wp.kernel(clone)


# --------------------------------------------------------------------------- module options


def test_set_and_get_module_options_by_name_and_caller():
    wp.set_module_options({"fast_math": True, "max_unroll": 4}, module="kdsl_t_opts")
    opts = wp.get_module_options("kdsl_t_opts")
    assert opts["fast_math"] is True and opts["max_unroll"] == 4
    assert opts["enable_backward"] is True  # Warp's defaults for the rest
    assert wp.get_module("kdsl_t_opts").options is opts
    wp.set_module_options({"lineinfo": True})  # the calling module: this test file
    assert wp.get_module_options()["lineinfo"] is True
    assert wp.get_module_options(__name__)["lineinfo"] is True


@pytest.mark.parametrize(
    "options, message",
    [
        ({"fast_maths": True}, "unknown option 'fast_maths'"),
        ({"mode": "fast"}, "'mode' must be 'release', 'debug' or None"),
        ({"enable_backward": 1}, "'enable_backward' must be True or False"),
        ({"max_unroll": -1}, "'max_unroll' must be a non-negative int"),
    ],
)
def test_bad_module_options_are_refused(options, message):
    with pytest.raises(wp.KdslError, match=re.escape(message)):
        wp.set_module_options(options, module="kdsl_t_bad")


def test_module_options_need_a_dict_and_a_module():
    with pytest.raises(wp.KdslError, match="takes a dict"):
        wp.set_module_options([("fast_math", True)], module="kdsl_t_bad")
    with pytest.raises(wp.KdslError, match="module must be"):
        wp.get_module_options(3.5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_module_options_reach_the_compile_options_and_kernel_options_win(backend):
    k = kernel_in(f"kdsl_t_fast_{backend}", _scale)
    own = kernel_in(f"kdsl_t_fast_{backend}", _scale, fast_math=False)
    a = wp.zeros(4, dtype=float)
    wp.launch(k, 4, inputs=[a, 2.0], backend=backend)
    assert "fast_math" not in launch_plan(k, "cpu", backend).options
    wp.set_module_options({"fast_math": True}, module=f"kdsl_t_fast_{backend}")
    # set after the kernel was defined: the next launch compiles with it
    wp.launch(k, 4, inputs=[a, 2.0], backend=backend)
    assert launch_plan(k, "cpu", backend).options["fast_math"] is True
    assert launch_plan(own, "cpu", backend).options["fast_math"] is False


@pytest.mark.parametrize("backend", BACKENDS)
def test_module_mode_debug_adds_bounds_checks(backend):
    k = kernel_in(f"kdsl_t_debug_{backend}", _oob)
    a = wp.zeros(4, dtype=float)
    wp.set_module_options({"mode": "debug"}, module=f"kdsl_t_debug_{backend}")
    assert config.compile_options(launch_plan(k, "cpu", backend).options).get("debug") is True
    with pytest.raises(wp.KdslRuntimeError):
        wp.launch(k, 4, inputs=[a], backend=backend)
    rel = kernel_in(f"kdsl_t_debug_{backend}", _oob, mode="release")  # the kernel's own option wins
    assert config.compile_options(launch_plan(rel, "cpu", backend).options).get("debug") is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_module_enable_backward_false_refuses_gradients(backend):
    k = kernel_in(f"kdsl_t_nobwd_{backend}", _scale)
    wp.set_module_options({"enable_backward": False}, module=f"kdsl_t_nobwd_{backend}")
    a = wp.array(np.ones(4, np.float32), requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(k, 4, inputs=[a, 2.0], backend=backend)
    with pytest.raises(wp.KdslError, match="enable_backward=False"):
        tape.backward(grads={a: wp.ones(4, dtype=float)})
    assert not modules.backward_enabled(k)
    assert modules.backward_enabled(
        kernel_in(f"kdsl_t_nobwd_{backend}", _scale, enable_backward=True)
    )


def test_load_module_compiles_every_kernel_ahead_of_time():
    k1 = kernel_in("kdsl_t_load", _scale)
    k2 = kernel_in("kdsl_t_load", _oob)
    k3 = kernel_in("kdsl_t_load.sub", _scale)
    assert [k.name for k in wp.get_module("kdsl_t_load").kernels] == ["_scale", "_oob"]
    wp.load_module("kdsl_t_load", device="cpu", recursive=True)
    for k in (k1, k2, k3):
        assert getattr(k, "_kdsl_plans", None), k.name
    wp.force_load(device=["cpu"], modules=[wp.get_module("kdsl_t_load")])


def test_load_module_without_kernels_is_an_error():
    with pytest.raises(wp.KdslError, match="defines no kdsl kernels"):
        wp.load_module("kdsl_t_empty")
    with pytest.raises(wp.KdslError, match=r"must be kdsl\.Module"):
        wp.force_load(device="cpu", modules=["kdsl_t_load"])


def test_clear_kernel_cache_recompiles(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path / "cache"))
    k = kernel_in("kdsl_t_clear", _scale)
    a = wp.zeros(4, dtype=float)
    wp.launch(k, 4, inputs=[a, 1.0], backend="cpu")
    assert any(p.suffix == ".kobj" for p in (tmp_path / "cache").iterdir())
    wp.clear_kernel_cache()
    assert not any(p.suffix == ".kobj" for p in (tmp_path / "cache").iterdir())
    builds = kcache.STATS.builds
    wp.launch(k, 4, inputs=[a, 1.0], backend="cpu")
    assert kcache.STATS.builds == builds + 1


def test_clear_kernel_cache_refuses_an_unsafe_directory(tmp_path, monkeypatch):
    d = tmp_path / "shared"
    d.mkdir()
    d.chmod(0o777)
    monkeypatch.setenv("KDSL_CACHE_DIR", str(d))
    with pytest.raises(wp.KdslError, match="writable by group or others"):
        wp.clear_kernel_cache()


# --------------------------------------------------------------------------- timing


@pytest.mark.parametrize("backend", BACKENDS)
def test_timing_records_each_launch(backend):
    k = kernel_in(f"kdsl_t_timing_{backend}", _scale)
    a = wp.zeros(16, dtype=float)
    wp.launch(k, 16, inputs=[a, 1.0], backend=backend)  # compiled outside the timing
    wp.timing_begin()
    wp.launch(k, 16, inputs=[a, 1.0], backend=backend)
    wp.launch(k, 16, inputs=[a, 1.0], backend=backend)
    results = wp.timing_end()
    assert [r.name for r in results] == ["forward kernel _scale"] * 2
    assert all(r.device.alias == "cpu" and r.elapsed > 0 and r.filter == wp.TIMING_KERNEL
               for r in results)  # fmt: skip
    wp.launch(k, 16, inputs=[a, 1.0], backend=backend)  # timing is off again
    assert wp.timing_end() == []
    wp.timing_begin(wp.TIMING_MEMCPY)  # kdsl records kernels only
    wp.launch(k, 16, inputs=[a, 1.0], backend=backend)
    assert wp.timing_end() == []


def test_timing_print_layout(capsys):
    wp.timing_print([])
    assert capsys.readouterr().out == "No activity\n"
    cpu = wp.get_device("cpu")
    rs = [wp.TimingResult(cpu, "forward kernel a", wp.TIMING_KERNEL, 1.5),
          wp.TimingResult(cpu, "forward kernel a", wp.TIMING_KERNEL, 0.5)]  # fmt: skip
    wp.timing_print(rs, indent="  ")
    out = capsys.readouterr().out
    assert "  Timeline:" in out
    assert "      1.500000 ms | cpu     | forward kernel a" in out
    assert "      2.000000 ms |       2 | forward kernel a" in out
    assert "      2.000000 ms |       2 | cpu" in out


def test_timing_begin_checks_its_filter():
    with pytest.raises(wp.KdslError, match="cuda_filter"):
        wp.timing_begin("all")


def test_scoped_timer_nested_dict_and_inactive(capsys):
    times: dict[str, list[float]] = {}
    k = kernel_in("kdsl_t_timer", _scale)
    a = wp.zeros(8, dtype=float)
    with (
        wp.ScopedTimer("outer", dict=times, synchronize=True) as outer,
        wp.ScopedTimer("inner", dict=times),
    ):
        wp.launch(k, 8, inputs=[a, 1.0])
    out = capsys.readouterr().out.splitlines()
    assert re.fullmatch(r"    inner took \d+\.\d\d ms", out[0])
    assert re.fullmatch(r"outer took \d+\.\d\d ms", out[1])
    assert len(times["outer"]) == 1 and times["outer"][0] == outer.elapsed > 0
    assert times["inner"][0] <= outer.elapsed
    with wp.ScopedTimer("quiet", print=False) as quiet:
        pass
    with wp.ScopedTimer("off", active=False) as off:
        pass
    assert capsys.readouterr().out == ""
    assert quiet.elapsed > 0 and off.elapsed == 0.0


def test_scoped_timer_reports_kernel_launches(capsys):
    k = kernel_in("kdsl_t_timer2", _scale)
    a = wp.zeros(8, dtype=float)
    wp.launch(k, 8, inputs=[a, 1.0])
    with wp.ScopedTimer("step", cuda_filter=wp.TIMING_ALL) as t:
        wp.launch(k, 8, inputs=[a, 1.0])
    assert [r.name for r in t.timing_results] == ["forward kernel _scale"]
    assert "Timeline:" in capsys.readouterr().out


# --------------------------------------------------------------------------- logging


class _Capture:
    def __init__(self):
        self.lines = []

    def debug(self, message):
        self.lines.append(("debug", message))

    def info(self, message):
        self.lines.append(("info", message))

    def warning(self, message, category=None, stacklevel=1):
        self.lines.append(("warning", message))

    def error(self, message):
        self.lines.append(("error", message))


def test_logger_scopes_and_levels():
    from kdsl.runtime.logger import log_debug, log_info

    cap = _Capture()
    with wp.ScopedLogger(cap):
        assert wp.get_logger() is cap
        with wp.ScopedTimer("t"):
            pass
        log_debug("hidden")  # below the default level
        with wp.ScopedLogLevel(wp.LOG_DEBUG):
            log_debug("shown")
        with wp.ScopedLogLevel(wp.LOG_ERROR):
            log_info("hidden too")
    assert wp.get_logger() is not cap
    assert [kind for kind, _ in cap.lines] == ["info", "debug"]
    assert cap.lines[0][1].startswith("t took ")
    assert config.log_level == wp.LOG_INFO


def test_bad_logger_is_refused():
    with pytest.raises(wp.KdslError, match="a logger needs callable"):
        wp.set_logger(object())
    with pytest.raises(wp.KdslError, match="ScopedLogLevel takes an int"):
        wp.ScopedLogLevel("debug")


# --------------------------------------------------------------------------- devices, mempool


def test_devices():
    assert wp.is_cpu_available()
    devices = wp.get_devices()
    assert devices[0] == wp.get_device("cpu")
    assert len(devices) == 1 + wp.get_cuda_device_count()
    assert wp.is_device_available(wp.get_device("cpu"))
    assert wp.is_device_available("cpu")
    assert not wp.is_device_available("cuda:99")
    if not wp.is_cuda_available():
        with pytest.raises(wp.KdslError, match="not available"):
            wp.get_cuda_device()
    with pytest.raises(wp.KdslError, match="int ordinal"):
        wp.get_cuda_device("0")


def test_mempool_on_the_cpu_answers_as_warp():
    assert not wp.is_mempool_supported("cpu")
    assert not wp.is_mempool_enabled("cpu")
    wp.set_mempool_enabled("cpu", False)  # a no-op, as in Warp
    for call in (
        lambda: wp.set_mempool_enabled("cpu", True),
        lambda: wp.set_mempool_release_threshold("cpu", 0.5),
        lambda: wp.get_mempool_release_threshold("cpu"),
        lambda: wp.get_mempool_used_mem_current("cpu"),
        lambda: wp.get_mempool_used_mem_high("cpu"),
    ):
        with pytest.raises(wp.KdslError, match="CUDA devices only"):
            call()


@cuda
def test_mempool_on_cuda():
    dev = "cuda:0"
    assert wp.is_mempool_supported(dev) and wp.is_mempool_enabled(dev)
    before = wp.get_mempool_used_mem_current(dev)
    a = wp.zeros(1 << 20, dtype=float, device=dev)
    assert wp.get_mempool_used_mem_current(dev) >= before + 4 * (1 << 20)
    assert wp.get_mempool_used_mem_high(dev) >= wp.get_mempool_used_mem_current(dev)
    del a
    with wp.ScopedMempool(dev, False):
        assert not wp.is_mempool_enabled(dev)
        used = wp.get_mempool_used_mem_current(dev)
        b = wp.zeros(1 << 20, dtype=float, device=dev)
        assert wp.get_mempool_used_mem_current(dev) == used  # not from the pool
        assert b.numpy().sum() == 0
    assert wp.is_mempool_enabled(dev)
    assert wp.get_mempool_release_threshold(dev) == 2**64 - 1
    wp.set_mempool_release_threshold(dev, 0)
    wp.synchronize()
    assert wp.get_mempool_release_threshold(dev) == 0
    wp.set_mempool_release_threshold(dev, 0.5)
    assert wp.get_mempool_release_threshold(dev) == int(0.5 * wp.get_device(dev).total_memory)
    with pytest.raises(wp.KdslError, match="threshold must be"):
        wp.set_mempool_release_threshold(dev, "1GB")


@cuda
def test_timing_on_cuda_uses_events():
    k = kernel_in("kdsl_t_cudatiming", _scale)
    a = wp.zeros(1 << 16, dtype=float, device="cuda:0")
    wp.launch(k, a.shape, inputs=[a, 1.0], device="cuda:0")
    wp.timing_begin()
    wp.launch(k, a.shape, inputs=[a, 1.0], device="cuda:0")
    (r,) = wp.timing_end()
    assert r.device.alias == "cuda:0" and r.elapsed > 0 and r.name == "forward kernel _scale"
    wp.load_module("kdsl_t_cudatiming", device="cuda:0")


# --------------------------------------------------------------------------- item 9


def _launch_here(k, *args, **kw):
    wp.launch(k, 4, *args, **kw)  # the line the error names


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    "inputs, message",
    [
        ("count", "takes 2 arguments"),
        ("dtype", "argument 0 'a'"),
        ("none", "argument 0 'a'"),
        ("ndim", "argument 0 'a'"),
        ("scalar", "argument 1 's'"),
    ],
)
def test_launch_errors_name_the_call_and_the_kernel(backend, inputs, message):
    k = wp.kernel(_scale)
    values = {
        "count": [wp.zeros(4, dtype=float)],
        "dtype": [wp.zeros(4, dtype=wp.int32), 1.0],
        "none": [None, 1.0],
        "ndim": [wp.zeros((2, 2), dtype=float), 1.0],
        "scalar": [wp.zeros(4, dtype=float), "x"],
    }[inputs]
    with pytest.raises(wp.KdslLaunchError) as info:
        _launch_here(k, inputs=values, backend=backend)
    err = info.value
    text = str(err)
    assert message in text
    assert err.loc.file == __file__ and err.func == "_launch_here"
    assert "wp.launch(k, 4, *args, **kw)  # the line the error names" in text
    assert f"kernel '_scale' is defined at:\n  File \"{__file__}\"" in text
    assert "def _scale(a: wp.array(dtype=float), s: float):" in text


@cuda
def test_launch_error_on_the_wrong_device_names_the_call():
    k = wp.kernel(_scale)
    a = wp.zeros(4, dtype=float, device="cpu")
    with pytest.raises(wp.KdslLaunchError) as info:
        _launch_here(k, inputs=[a, 1.0], device="cuda:0")
    assert info.value.loc.file == __file__ and "is defined at" in str(info.value)


def test_recorded_launch_errors_name_the_call():
    k = wp.kernel(_scale)
    cmd = wp.launch(k, 4, inputs=[wp.zeros(4, dtype=float), 1.0], record_cmd=True)
    with pytest.raises(wp.KdslLaunchError) as info:
        cmd.set_param_at_index(1, "x")
    assert info.value.loc.file == __file__


def test_timer_output_goes_to_a_custom_stream():
    buf = io.StringIO()

    class ToBuf(_Capture):
        def info(self, message):
            buf.write(message + "\n")

    with wp.ScopedLogger(ToBuf()), wp.ScopedTimer("x"):
        pass
    assert buf.getvalue().startswith("x took ")
