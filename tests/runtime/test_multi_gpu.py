"""Several GPUs in one process: peer and mempool access, copies between devices, launches
on each device (issue 19, item 1).

The CPU rules run everywhere; the two-GPU tests are skipped unless two CUDA devices exist.
"""

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError, KdslRuntimeError, KdslValueError

two_gpus = pytest.mark.skipif(wp.get_cuda_device_count() < 2, reason="needs two CUDA devices")

QUERIES = [
    wp.is_peer_access_supported,
    wp.is_peer_access_enabled,
    wp.is_mempool_access_supported,
    wp.is_mempool_access_enabled,
]


@wp.kernel
def _scale(a: wp.array(dtype=wp.float32), s: wp.float32):
    i = wp.tid()
    a[i] = a[i] * s


@pytest.fixture(autouse=True)
def _restore_default_device():
    saved = wp.get_device()
    yield
    wp.set_device(saved)


# --- CPU rules (run everywhere) ----------------------------------------------------------------


def test_devices_list_the_cpu_first():
    devices = wp.get_devices()
    assert devices[0] == "cpu"
    assert len(devices) == 1 + wp.get_cuda_device_count()
    assert [d.alias for d in devices[1:]] == [f"cuda:{i}" for i in range(len(devices) - 1)]


@pytest.mark.parametrize("query", QUERIES, ids=lambda f: f.__name__)
def test_access_queries_are_false_with_the_cpu(query):
    assert query("cpu", "cpu") is False


@pytest.mark.parametrize("setter", [wp.set_peer_access_enabled, wp.set_mempool_access_enabled])
def test_enabling_access_with_the_cpu_is_a_value_error(setter):
    with pytest.raises(KdslValueError, match="between CUDA devices only"):
        setter("cpu", "cpu", True)
    setter("cpu", "cpu", False)  # disabling what cannot exist does nothing, as in Warp


@pytest.mark.parametrize("scoped", [wp.ScopedPeerAccess, wp.ScopedMempoolAccess])
def test_scoped_access_off_on_the_cpu_is_a_no_op(scoped):
    with scoped("cpu", "cpu", False):
        pass
    with pytest.raises(KdslValueError), scoped("cpu", "cpu", True):
        pass


@pytest.mark.skipif(wp.get_cuda_device_count() > 0, reason="checks the CPU-only message")
def test_access_to_a_missing_gpu_names_the_devices_there_are():
    with pytest.raises(KdslError, match="no CUDA devices"):
        wp.is_peer_access_supported("cuda:0", "cpu")


def test_scoped_device_runs_a_cpu_launch():
    a = wp.array(np.arange(4, dtype=np.float32), device="cpu")
    with wp.ScopedDevice("cpu"):
        wp.launch(_scale, dim=4, inputs=[a, 2.0])
    np.testing.assert_array_equal(a.numpy(), [0, 2, 4, 6])


# --- two GPUs ----------------------------------------------------------------------------------


def _peers_or_skip():
    if not wp.is_peer_access_supported("cuda:0", "cuda:1"):
        pytest.skip("these GPUs have no peer access")


@two_gpus
def test_a_device_and_itself():
    for query in QUERIES:
        assert query("cuda:1", "cuda:1") is True
    assert wp.is_peer_access_supported("cuda:0", "cpu") is False
    assert wp.is_peer_access_supported("cuda:0", "cuda:1") == wp.get_device("cuda:1").can_access(
        "cuda:0"
    )


@two_gpus
def test_peer_access_on_and_off_and_scoped():
    _peers_or_skip()
    saved = wp.is_peer_access_enabled("cuda:0", "cuda:1")
    wp.set_peer_access_enabled("cuda:0", "cuda:1", False)
    assert wp.is_peer_access_enabled("cuda:0", "cuda:1") is False
    with wp.ScopedPeerAccess("cuda:0", "cuda:1", True):
        assert wp.is_peer_access_enabled("cuda:0", "cuda:1") is True
        wp.set_peer_access_enabled("cuda:0", "cuda:1", True)  # twice is fine
    assert wp.is_peer_access_enabled("cuda:0", "cuda:1") is False
    wp.set_peer_access_enabled("cuda:0", "cuda:1", False)  # twice is fine
    wp.set_peer_access_enabled("cuda:0", "cuda:1", saved)


@two_gpus
def test_mempool_access_is_its_own_switch():
    _peers_or_skip()
    assert wp.is_mempool_access_supported("cuda:0", "cuda:1")
    with wp.ScopedPeerAccess("cuda:0", "cuda:1", False):
        with wp.ScopedMempoolAccess("cuda:0", "cuda:1", True):
            assert wp.is_mempool_access_enabled("cuda:0", "cuda:1") is True
            assert wp.is_peer_access_enabled("cuda:0", "cuda:1") is False
            # A peer copy with the pool reachable.
            src = wp.array(np.arange(8, dtype=np.float32), device="cuda:0")
            dst = wp.zeros(8, dtype=wp.float32, device="cuda:1")
            wp.copy(dst, src)
            np.testing.assert_array_equal(dst.numpy(), np.arange(8))
        assert wp.is_mempool_access_enabled("cuda:0", "cuda:1") is False


@two_gpus
def test_a_kernel_on_each_device():
    a0 = wp.array(np.ones(64, dtype=np.float32), device="cuda:0")
    a1 = wp.array(np.ones(64, dtype=np.float32), device="cuda:1")
    with wp.ScopedDevice("cuda:0"):
        wp.launch(_scale, dim=64, inputs=[a0, 2.0])
    with wp.ScopedDevice("cuda:1"):
        wp.launch(_scale, dim=64, inputs=[a1, 3.0])
        assert wp.get_device() == "cuda:1"
    wp.launch(_scale, dim=64, inputs=[a1, 5.0], device="cuda:1")
    np.testing.assert_array_equal(a0.numpy(), np.full(64, 2.0))
    np.testing.assert_array_equal(a1.numpy(), np.full(64, 15.0))


@two_gpus
@pytest.mark.parametrize("peer", [False, True], ids=["through-host", "peer"])
def test_copies_both_ways(peer):
    if peer:
        _peers_or_skip()
    n = 1 << 16
    data = np.random.default_rng(1).random(n, dtype=np.float32)
    with wp.ScopedPeerAccess("cuda:0", "cuda:1", peer) if peer else _nothing():
        a0 = wp.array(data, device="cuda:0")
        with wp.ScopedDevice("cuda:0"):
            wp.launch(_scale, dim=n, inputs=[a0, 2.0])  # the copy must wait for this
        a1 = wp.zeros(n, dtype=wp.float32, device="cuda:1")
        wp.copy(a1, a0)
        with wp.ScopedDevice("cuda:1"):
            wp.launch(_scale, dim=n, inputs=[a1, 3.0])
        back = wp.zeros(n, dtype=wp.float32, device="cuda:0")
        wp.copy(back, a1, dest_offset=0, src_offset=0, count=n)
        strided = wp.zeros(2 * n, dtype=wp.float32, device="cuda:1")[::2]
        wp.copy(strided, a0)
        np.testing.assert_allclose(back.numpy(), data * 6.0, rtol=1e-6)
        np.testing.assert_allclose(strided.numpy(), data * 2.0, rtol=1e-6)
        np.testing.assert_allclose(a1.to("cuda:0").numpy(), data * 6.0, rtol=1e-6)


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None


@two_gpus
def test_an_array_of_another_device_in_a_launch_is_an_error():
    a0 = wp.zeros(4, dtype=wp.float32, device="cuda:0")
    with pytest.raises(
        KdslError, match=r"expected an array on device 'cuda:1', got one on 'cuda:0'"
    ):
        wp.launch(_scale, dim=4, inputs=[a0, 1.0], device="cuda:1")


@two_gpus
def test_enabling_unsupported_peer_access_is_a_runtime_error():
    if wp.is_peer_access_supported("cuda:0", "cuda:1"):
        pytest.skip("these GPUs have peer access")
    with pytest.raises(KdslRuntimeError, match="cannot access"):
        wp.set_peer_access_enabled("cuda:0", "cuda:1", True)


# --- IPC: sharing arrays and events between processes ------------------------------------------

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")


def test_ipc_is_for_cuda_memory_only():
    with pytest.raises(KdslError, match="IPC shares CUDA memory only"):
        wp.zeros(3, device="cpu").ipc_handle()
    with pytest.raises(KdslError, match="IPC shares CUDA memory only"):
        wp.from_ipc_handle(bytes(64), wp.float32, (4,), device="cpu")
    with pytest.raises(KdslError, match="IPC shares CUDA memory only"):
        wp.event_from_ipc_handle(bytes(64), device="cpu")


@cuda
def test_ipc_handles_refuse_pool_views_and_plain_events():
    with pytest.raises(KdslError, match="ScopedMempool"):
        wp.zeros(8, device="cuda:0").ipc_handle()
    with wp.ScopedMempool("cuda:0", False):
        a = wp.zeros(8, device="cuda:0")
    assert len(a.ipc_handle()) == 64
    with pytest.raises(KdslError, match="view that does not start"):
        a[2:].ipc_handle()
    with pytest.raises(KdslError, match="interprocess=True"):
        wp.Event("cuda:0").ipc_handle()
    with pytest.raises(KdslError, match="64 bytes"):
        wp.from_ipc_handle(b"short", wp.float32, (8,), device="cuda:0")
    with pytest.raises(KdslError, match="could not open"):  # CUDA: not in the same process
        wp.from_ipc_handle(a.ipc_handle(), wp.float32, (8,), device="cuda:0")


_CHILD = """
import sys
import kdsl as wp

@wp.kernel
def triple(a: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    a[i] = a[i] * 3.0

a = wp.from_ipc_handle(bytes.fromhex(sys.argv[1]), wp.vec2, (16,), device="cuda:0")
done = wp.event_from_ipc_handle(bytes.fromhex(sys.argv[2]), device="cuda:0")
wp.get_stream("cuda:0").wait_event(done)  # the parent's launch comes first
wp.launch(triple, dim=16, inputs=[a], device="cuda:0")
wp.synchronize_device("cuda:0")
print(float(a.numpy().sum()))
"""


@cuda
def test_an_array_and_an_event_shared_with_another_process(tmp_path):
    import subprocess
    import sys

    script = tmp_path / "child.py"
    script.write_text(_CHILD)
    with wp.ScopedMempool("cuda:0", False):
        a = wp.array(np.ones((16, 2), dtype=np.float32), dtype=wp.vec2, device="cuda:0")
    with wp.ScopedDevice("cuda:0"):
        wp.launch(_double_vec2, dim=16, inputs=[a])
    done = wp.Event("cuda:0", interprocess=True)
    wp.get_stream("cuda:0").record_event(done)
    out = subprocess.run(
        [sys.executable, str(script), a.ipc_handle().hex(), done.ipc_handle().hex()],
        capture_output=True, text=True, timeout=240, check=False,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert float(out.stdout.split()[-1]) == 16 * 2 * 6.0
    np.testing.assert_array_equal(a.numpy(), np.full((16, 2), 6.0))


@wp.kernel
def _double_vec2(a: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    a[i] = a[i] * 2.0


@two_gpus
def test_can_access_follows_peer_access():
    _peers_or_skip()
    a0 = wp.zeros(4, device="cuda:0")
    with wp.ScopedPeerAccess("cuda:0", "cuda:1", False):
        assert not wp.can_access("cuda:1", a0)
        with wp.ScopedPeerAccess("cuda:0", "cuda:1", True):
            assert wp.can_access("cuda:1", a0)
        with wp.ScopedMempoolAccess("cuda:0", "cuda:1", True):
            assert wp.can_access("cuda:1", a0)
    assert wp.can_access("cuda:0", a0) and not wp.can_access("cpu", a0)
