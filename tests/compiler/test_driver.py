"""The compile driver: stages, instrumentation, cache keys and the verification policy."""

from __future__ import annotations

import pytest

from kdsl import config
from kdsl.backends import get_backend
from kdsl.backends.base import Backend, CompiledKernel
from kdsl.compiler import compile_kernel, driver, lower
from kdsl.errors import KdslError
from kdsl.ir import parse_module

SRC = """func.func @k(%x: array<f32, 1>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %0 = kd.load %x, %i : f32
  %1 = arith.add %0, %0 : f32
  kd.store %1, %x, %i
  func.return
}
"""


class Recording(Backend):
    """A backend that records what the driver hands it."""

    name = "recording"
    version = "1"
    capabilities = frozenset({"fp32", "fp64", "int64", "atomics"})
    emit_stages = ("text",)
    target_options = ("arch",)

    def __init__(self) -> None:
        self.builds: list[str] = []
        self.jobs: list = []

    def devices(self) -> list[str]:
        return ["cpu"]

    def emit(self, module, stage, options, checked):
        return f"checked={checked}"

    def build(self, job, target):
        self.builds.append(target)
        return f"binary for {target}".encode()

    def load(self, job):
        self.jobs.append(job)
        payload = job.artifact(job.options.get("arch", "t0"))
        return CompiledKernel(self.name, job.symbol, job.module, payload)

    def launch(self, compiled, dims, args, stream=None):
        pass


@pytest.mark.parametrize("backend", ["interp", "cpu", "cuda"])
def test_kir_opt_holds_the_debug_checks_on_every_backend(backend):
    b = get_backend(backend)
    release = lower(b, parse_module(SRC), "kir-opt")
    debug = lower(b, parse_module(SRC), "kir-opt", {"debug": True})
    assert "kd.check_bounds" not in release
    assert "kd.check_bounds" in debug


def test_binaries_are_built_once_per_key_and_target(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path))
    b = Recording()
    a = compile_kernel(b, parse_module(SRC), "k", {"tag": "driver-test"})
    again = compile_kernel(b, parse_module(SRC), "k", {"tag": "driver-test"})
    assert a.payload == again.payload == b"binary for t0"
    assert b.builds == ["t0"]  # the second compile was a cache hit
    other = compile_kernel(b, parse_module(SRC), "k", {"tag": "driver-test", "arch": "t1"})
    assert other.payload == b"binary for t1" and b.builds == ["t0", "t1"]
    first, _, third = b.jobs
    # A target option selects the target; it is not also an option in the key.
    assert first.key("t1") == third.key("t1")
    assert first.key("t0") != first.key("t1")


def test_options_and_checks_key_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path))  # a fresh disk layer: builds counted
    b = Recording()
    compile_kernel(b, parse_module(SRC), "k", {"tag": "checks-key"})
    compile_kernel(b, parse_module(SRC), "k", {"tag": "checks-key", "debug": True})
    j0, j1 = b.jobs
    assert not j0.checked and j1.checked
    assert j0.key("t0") != j1.key("t0")
    assert len(b.builds) == 2  # one binary each: the checked build is cached apart


def test_a_backend_without_binaries_is_never_asked_to_build():
    compiled = compile_kernel(get_backend("interp"), parse_module(SRC), "k")
    assert compiled.symbol == "k" and compiled.metadata["tid_ndims"] == [1]


def test_bad_targets_and_stages_are_clear_errors():
    b = Recording()
    with pytest.raises(KdslError, match="name the kernel"):
        compile_kernel(b, parse_module(SRC))
    with pytest.raises(KdslError, match="expected a kernel or an IR module"):
        compile_kernel(b, "not a kernel", "k")
    with pytest.raises(KdslError, match="no stage 'ptx'"):
        lower(b, parse_module(SRC), "ptx")
    assert lower(b, parse_module(SRC), "text", {"verify_fp": True}) == "checked=True"


@pytest.mark.parametrize(
    "policy, options, expected",
    [("auto", {"debug": True}, True), ("auto", {}, None), ("end", {"debug": True}, None),
     ("each", {}, None)],
)  # fmt: skip
def test_a_kernels_own_debug_option_verifies_after_every_pass(
    monkeypatch, policy, options, expected
):
    monkeypatch.setattr(config, "verify_passes", policy)
    assert driver.verify_each(options) is expected
    seen = []
    real = driver.run_pipeline

    def spy(module, pipeline, **kw):
        seen.append(kw.get("verify_each"))
        return real(module, pipeline, **kw)

    monkeypatch.setattr(driver, "run_pipeline", spy)
    compile_kernel(get_backend("interp"), parse_module(SRC), "k", options)
    assert seen and all(v is expected for v in seen)
