"""A stand-in for frontend kernels: IR text plus the attributes launch reads."""

import pytest

from kdsl.ir import parse_module


class IRKernel:
    """What ``kdsl.launch`` needs from a kernel, built from IR text."""

    def __init__(self, src: str, key: str) -> None:
        self.src = src
        self.key = key
        self.name = key
        func = parse_module(src).get_func(key)
        args = func.regions[0].block.args
        self.arg_names = [a.name_hint for a in args]
        self.arg_types = [a.type for a in args]
        ndims = {op.attrs["ndim"] for op in func.walk() if op.name == "kd.tid"}
        self.tid_ndim = max(ndims, default=0)
        self.builds = 0

    def build_module(self):
        self.builds += 1
        return parse_module(self.src)


SAXPY = """func.func @saxpy(%x: array<f32, 1>, %y: array<f32, 1>, %a: f32) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %0 = kd.load %x, %i : f32
  %1 = kd.load %y, %i : f32
  %2 = arith.mul %a, %0 : f32
  %3 = arith.add %2, %1 : f32
  kd.store %3, %y, %i
  func.return
}
"""

# One parameter of each kind that launch converts: arrays of vectors, ints, vectors.
MIXED = """func.func @mixed(%p: array<vec<3, f32>, 1>, %n: i32, %v: vec<3, f32>, %m: array<f32, 2>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 1} : i32
  %0 = kd.load %p, %i : vec<3, f32>
  %1 = arith.add %0, %v : vec<3, f32>
  kd.store %1, %p, %i
  func.return
}
"""

GRID = """func.func @grid(%out: array<i32, 2>) -> () {kind = "kernel"} {
  %i = kd.tid {dim = 0, ndim = 2} : i32
  %j = kd.tid {dim = 1, ndim = 2} : i32
  %k = kd.tid {dim = 0, ndim = 1} : i32
  kd.store %k, %out, %i, %j
  func.return
}
"""


@pytest.fixture(autouse=True)
def _private_kernel_cache(tmp_path_factory, monkeypatch):
    """Every runtime test gets its own kernel cache dir, never the user's real one."""
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path_factory.mktemp("kdsl-cache")))
    monkeypatch.delenv("KDSL_CACHE", raising=False)


@pytest.fixture
def saxpy():
    return IRKernel(SAXPY, "saxpy")


@pytest.fixture
def mixed():
    return IRKernel(MIXED, "mixed")


@pytest.fixture
def grid():
    return IRKernel(GRID, "grid")
