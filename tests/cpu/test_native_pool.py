"""The native thread pool: launches split over threads without Python in the hand-off."""

from __future__ import annotations

import os
import threading
import warnings

import numpy as np
import pytest

import kdsl as wp
from kdsl.backends.base import SupportCode
from kdsl.backends.cpu import BACKEND, native_pool, pool
from kdsl.compiler import load_support

NATIVE = native_pool.source() is not None
needs_native = pytest.mark.skipif(not NATIVE, reason="no native pool on this platform")


@wp.kernel
def add_index(a: wp.array(dtype=wp.int64)):
    i = wp.tid()
    a[i] = a[i] + wp.int64(i)


@pytest.fixture
def forced_pool():
    """Every launch of more than one thread goes to the pool (no inline choice)."""
    old = pool.min_parallel, pool.adaptive
    pool.min_parallel, pool.adaptive = 1, False
    try:
        yield
    finally:
        pool.min_parallel, pool.adaptive = old


def _launch(n: int, times: int = 1) -> np.ndarray:
    a = wp.zeros(n, dtype=wp.int64)
    for _ in range(times):
        wp.launch(add_index, n, [a])
    return a.numpy()


@needs_native
def test_a_split_launch_runs_on_the_native_pool(forced_pool, monkeypatch):
    _launch(4)  # the first launch loads the runtime
    assert pool.native() is not None

    def python_pool(*args, **kwargs):
        raise AssertionError("the Python pool ran a native kernel")

    monkeypatch.setattr(pool, "run", python_pool)
    for n in (2, 3, 17, 1000, 1 << 16):  # fewer threads than chunks, uneven splits
        np.testing.assert_array_equal(_launch(n, times=3), 3 * np.arange(n))


@needs_native
@pytest.mark.parametrize("threads", [1, 2, 5])
def test_every_thread_count_covers_the_range_once(forced_pool, threads):
    old = pool.num_threads()
    pool.set_num_threads(threads)
    try:
        for n in (1, 4, 99, 4096):
            np.testing.assert_array_equal(_launch(n, times=2), 2 * np.arange(n))
    finally:
        pool.set_num_threads(old)


@needs_native
def test_launching_threads_share_the_pool_or_run_inline(forced_pool):
    n, results, errors = 1 << 12, [], []

    def work():
        try:
            results.append(_launch(n, times=25))
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(results) == 6
    for r in results:
        np.testing.assert_array_equal(r, 25 * np.arange(n))


@needs_native
@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork")
@pytest.mark.filterwarnings("ignore:os.fork")  # other tests' libraries (JAX) start threads
def test_a_forked_child_starts_its_own_workers(forced_pool):
    _launch(64)
    pid = os.fork()
    if pid == 0:  # the child: none of the parent's workers exist here
        try:
            ok = bool((_launch(1 << 12, times=2) == 2 * np.arange(1 << 12)).all())
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


def test_kdsl_cpu_pool_python_keeps_the_python_workers(monkeypatch):
    monkeypatch.setenv("KDSL_CPU_POOL", "python")
    assert BACKEND.support() == []
    monkeypatch.delenv("KDSL_CPU_POOL")
    assert [c.name for c in BACKEND.support()] == (["native-pool"] if NATIVE else [])


class _BrokenSupport:
    name, version = "broken-support-test", "1"

    def code_version(self):
        return "1"

    def cache_target(self, target):
        return target

    def support(self):
        def build():
            raise RuntimeError("no compiler today")

        return [SupportCode("runtime", "text", "host", build, lambda data: data)]


def test_support_code_that_fails_is_a_warning(tmp_path, monkeypatch):
    monkeypatch.setenv("KDSL_CACHE_DIR", str(tmp_path))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_support(_BrokenSupport())
        load_support(_BrokenSupport())  # once per process: no second warning
    messages = [str(w.message) for w in caught]
    assert len(messages) == 1 and "no compiler today" in messages[0]
