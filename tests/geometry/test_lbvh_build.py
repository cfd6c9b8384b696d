"""The lbvh build (``kdsl.geometry.lbvh``): the bottom-up hierarchy and preorder kernels
give exactly the binary radix tree of a recursive NumPy/Python reference over the same
64-bit keys (group, Morton code, index), with duplicates and groups; a rebuild over moved
boxes reuses every buffer and gives a fresh build's tree; a build reads nothing back
and allocates one block, a rebuild neither allocates nor prepares; cuda variants on
the GPU machine."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.geometry import lbvh, recycle
from kdsl.geometry.device_tree import UNUSED
from kdsl.runtime.array import array
from kdsl.utils.merge_sort import merge_passes
from tests.geometry.graph_stand_in import counting_capture

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]


def _spread(v: int) -> int:
    return sum(((v >> b) & 1) << (3 * b) for b in range(10))


def _grid_boxes(rng, n: int, cells: int):
    """Boxes whose centres sit at cell centres of a 1024^3 grid (``cells`` distinct
    coordinates per axis, so duplicates when few), with centres 0 and 1023 present on
    every axis: the centres' bounds are [0, 1023], the quantization the identity."""
    q = rng.integers(0, cells, (n, 3)) * (1023 // max(cells - 1, 1))
    q[0], q[-1] = 0, 1023
    c = q.astype(np.float32)
    return c - np.float32(0.25), c + np.float32(0.25), q


def _reference(keys: list[int], leaf_size: int, group_shift: int):
    """skip, first, count of the preorder tree over the sorted distinct ``keys``."""
    skip, first, count = [], [], []

    def clz(x: int) -> int:
        return 64 - x.bit_length()

    def emit(a: int, b: int) -> None:
        me = len(skip)
        skip.append(0)
        if b - a + 1 <= leaf_size and keys[a] >> group_shift == keys[b] >> group_shift:
            first.append(a)
            count.append(b - a + 1)
        else:
            first.append(-1)
            count.append(0)
            d = clz(keys[a] ^ keys[b])
            split = max(i for i in range(a, b) if clz(keys[a] ^ keys[i]) > d)
            emit(a, split)
            emit(split + 1, b)
        skip[me] = len(skip)

    emit(0, len(keys) - 1)
    return skip, first, count


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("use_scan", [True, False])  # (a CPU's numbering, a GPU's)
@pytest.mark.parametrize(("n", "cells", "leaf_size", "num_groups"), [
    (1, 2, 1, 0), (2, 2, 1, 0), (300, 1024, 1, 0), (300, 1024, 4, 0), (400, 3, 1, 0),
    (400, 3, 3, 0), (500, 16, 2, 5), (257, 1024, 1, 3),
])  # fmt: skip
def test_tree_is_the_radix_tree_of_the_keys(device, use_scan, n, cells, leaf_size, num_groups):
    rng = np.random.default_rng(n + cells)
    lo, hi, q = _grid_boxes(rng, n, cells)
    groups = rng.integers(0, num_groups, n).astype(np.int32) if num_groups else None
    drop, index_bits, group_shift = lbvh.key_layout(n, num_groups)
    morton = [(_spread(int(x)) << 2 | _spread(int(y)) << 1 | _spread(int(z))) >> drop
              for x, y, z in q]
    keys = sorted(m << index_bits | i | (int(groups[i]) << group_shift if num_groups else 0)
                  for i, m in enumerate(morton))  # fmt: skip
    skip, first, count = _reference(keys, leaf_size, group_shift if num_groups else 63)
    g = None if groups is None else wp.array(groups, dtype=wp.int32, device=device)
    t = lbvh.build_lbvh(wp.array(lo, dtype=wp.vec3, device=device),
                        wp.array(hi, dtype=wp.vec3, device=device), leaf_size, g, num_groups,
                        bottom_up=True, use_scan=use_scan)  # fmt: skip
    m = t.num_nodes
    assert m == len(skip) and t.slots == 2 * n - 1
    np.testing.assert_array_equal(t.skip.numpy()[:m], skip)
    np.testing.assert_array_equal(t.first.numpy()[:m], first)
    np.testing.assert_array_equal(t.count.numpy()[:m], count)
    np.testing.assert_array_equal(t.items.numpy(), [k & ((1 << index_bits) - 1) for k in keys])
    assert np.all(t.first.numpy()[m:] == UNUSED) and np.all(t.nodes.numpy()["first"][m:] == UNUSED)
    nodes = t.nodes.numpy()[:m]  # packed links and bounds: the union of the items below
    items = t.items.numpy()
    for k in range(m):
        end = skip[k] if first[k] < 0 else k + 1
        under = [items[first[j] + c] for j in range(k, end) if first[j] >= 0
                 for c in range(count[j])]  # fmt: skip
        np.testing.assert_array_equal(nodes["lower"][k], lo[under].min(axis=0))
        np.testing.assert_array_equal(nodes["upper"][k], hi[under].max(axis=0))
        assert nodes["next"][k] == (count[k] if first[k] >= 0 else skip[k])
        assert nodes["first"][k] == (first[k] if first[k] >= 0 else -1 - skip[k + 1])
    parents = t.parent.numpy()  # each node's parent: the node whose children it is
    assert parents[0] == -1 and np.all(parents[m:] == -1)
    for k in range(m):
        if first[k] < 0:
            assert parents[k + 1] == k and parents[skip[k + 1]] == k
    if num_groups:  # each group's root: the top node over exactly its boxes
        roots = t.group_roots.numpy()
        for grp in range(num_groups):
            under = np.flatnonzero(groups == grp)
            if len(under) == 0:
                assert roots[grp] == -1
                continue
            r = roots[grp]
            end = skip[r] if first[r] < 0 else r + 1
            got = [items[first[j] + c] for j in range(r, end) if first[j] >= 0
                   for c in range(count[j])]  # fmt: skip
            assert sorted(got) == under.tolist()


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_rebuild_reuses_buffers_and_matches_a_fresh_build(device, leaf_size):
    rng = np.random.default_rng(3)
    n = 3000
    lo = wp.array(rng.random((n, 3)).astype(np.float32), dtype=wp.vec3, device=device)
    hi = wp.array(lo.numpy() + 0.01, dtype=wp.vec3, device=device)
    bvh = wp.Bvh(lo, hi, constructor="lbvh", leaf_size=leaf_size)
    nodes, tree = bvh._nodes, bvh._tree
    for step in range(3):  # each build must leave its counters zeroed for the next
        c = rng.random((n, 3)).astype(np.float32) * (step + 1)
        lo.assign(wp.array(c, dtype=wp.vec3, device=device))
        hi.assign(wp.array(c + 0.02, dtype=wp.vec3, device=device))
        bvh.rebuild()
        assert bvh._nodes is nodes and bvh._tree is tree
        fresh = wp.Bvh(lo, hi, constructor="lbvh", leaf_size=leaf_size)
        assert tree.num_nodes == fresh._tree.num_nodes
        np.testing.assert_array_equal(bvh._nodes.numpy(), fresh._nodes.numpy())
        np.testing.assert_array_equal(tree.items.numpy(), fresh._tree.items.numpy())
        bvh.refit()  # the refit's counters too
        np.testing.assert_array_equal(bvh._nodes.numpy(), fresh._nodes.numpy())


@pytest.mark.parametrize("device", DEVICES)
def test_build_reads_nothing_back_and_rebuild_prepares_nothing(device, monkeypatch):
    n = 5000
    rng = np.random.default_rng(5)
    lo = wp.array(rng.random((n, 3)).astype(np.float32), dtype=wp.vec3, device=device)
    hi = wp.array(lo.numpy() + 0.01, dtype=wp.vec3, device=device)
    wp.Bvh(lo, hi, constructor="lbvh")  # compiles
    calls = {"numpy": 0, "alloc": 0, "launch": 0, "fill": 0}
    real_numpy = array.numpy

    def counting(name, fn):
        def wrapped(*a, **k):
            calls[name] += 1
            return fn(*a, **k)
        return wrapped

    monkeypatch.setattr(array, "numpy", counting("numpy", real_numpy))
    monkeypatch.setattr(lbvh, "empty", counting("alloc", lbvh.empty))
    monkeypatch.setattr(array, "zero_", counting("fill", array.zero_))
    monkeypatch.setattr(lbvh, "launch", counting("launch", lbvh.launch))
    recycle.clear()  # (the first BVH's build, kept when it was collected)
    bvh = wp.Bvh(lo, hi, constructor="lbvh")
    assert calls == {"numpy": 0, "alloc": 1, "launch": 4, "fill": 1}  # one block, four kernels
    calls.update(numpy=0, alloc=0, launch=0, fill=0)
    bvh.rebuild()
    assert calls == {"numpy": 0, "alloc": 0, "launch": 0, "fill": 0}
    del bvh  # a fresh BVH over the same boxes takes the collected one's build
    bvh = wp.Bvh(lo, hi, constructor="lbvh")
    assert calls == {"numpy": 0, "alloc": 0, "launch": 0, "fill": 0}
    monkeypatch.setattr(array, "numpy", real_numpy)
    assert bvh._tree.num_nodes == 2 * n - 1  # read back on demand only


def test_key_layout_makes_room_for_groups_and_refuses_too_many():
    assert lbvh.key_layout(200_000, 0) == (0, 18, 63)
    assert lbvh.key_layout(200_000, 5) == (0, 18, 48)
    assert lbvh.key_layout(2**31, 2**12) == (12, 31, 49)  # fewer Morton bits
    with pytest.raises(KdslError, match="no key bits"):
        lbvh.key_layout(2**31, 2**31)


@pytest.mark.parametrize("leaf_size", [1, 3])
@pytest.mark.parametrize("num_groups", [0, 4])
def test_both_numberings_give_one_tree_on_adversarial_boxes(leaf_size, num_groups):
    """The scan numbering (a CPU's) and the walk numbering (a GPU's) write the same
    arrays, bit for bit, over NaN boxes, duplicates and a degenerate axis."""
    rng = np.random.default_rng(leaf_size + num_groups)
    n = 1500
    c = rng.random((n, 3)).astype(np.float32)
    c[: n // 3] = c[0]  # a third at one centre
    c[:, 2] = 0.5  # a flat axis
    lo, hi = c - np.float32(0.01), c + np.float32(0.01)
    lo[rng.integers(0, n, 20)] = np.nan  # NaN boxes
    groups = None
    if num_groups:
        groups = wp.array(rng.integers(0, num_groups, n).astype(np.int32))
    trees = [lbvh.build_lbvh(wp.array(lo, dtype=wp.vec3), wp.array(hi, dtype=wp.vec3),
                             leaf_size, groups, num_groups, bottom_up=True, use_scan=scan)
             for scan in (True, False)]  # fmt: skip
    a, b = trees
    assert a.num_nodes == b.num_nodes
    for name in ("skip", "first", "count", "items", "group_roots", "parent"):
        np.testing.assert_array_equal(getattr(a, name).numpy(), getattr(b, name).numpy())
    assert a.nodes.numpy().tobytes() == b.nodes.numpy().tobytes()


def gpu_config_tree(lo: np.ndarray, hi: np.ndarray, leaf_size: int, groups, num_groups: int):
    """An lbvh tree built on the CPU as a GPU builds it (bottom-up parents, no scan)."""
    return lbvh.build_lbvh(wp.array(lo, dtype=wp.vec3), wp.array(hi, dtype=wp.vec3), leaf_size,
                           groups, num_groups, bottom_up=True, use_scan=False)  # fmt: skip


def tree_arrays(t) -> list[bytes]:
    names = ("skip", "first", "count", "items", "group_roots", "parent")
    return [getattr(t, k).numpy().tobytes() for k in names] + [t.nodes.numpy().tobytes()]


@pytest.mark.parametrize("leaf_size", [1, 4])
@pytest.mark.parametrize("num_groups", [0, 3])
def test_kernel_sort_builds_the_same_tree(monkeypatch, leaf_size, num_groups):
    """The kdsl merge sort (a GPU's, from a build's first run: its merges two prepared
    launches) and ``SortKeys`` sort the distinct keys alike: one tree bit for bit,
    duplicates and NaN boxes included, at the first run and at a rebuild."""
    rng = np.random.default_rng(leaf_size + 10 * num_groups)
    n = 2500
    c = rng.random((n, 3)).astype(np.float32)
    c[: n // 4] = c[0]
    lo, hi = c - np.float32(0.01), c + np.float32(0.01)
    lo[rng.integers(0, n, 10)] = np.nan
    groups = wp.array(rng.integers(0, num_groups, n).astype(np.int32)) if num_groups else None
    trees = []
    for kernels in (False, True):
        monkeypatch.setattr(lbvh, "device_sort_on", lambda device, k=kernels: k)
        trees.append(gpu_config_tree(lo, hi, leaf_size, groups, num_groups))
    assert tree_arrays(trees[0]) == tree_arrays(trees[1])  # SortKeys, the merge sort
    trees[1].rebuild()  # the merge sort again, its merges' run lengths rewritten
    steps = trees[1].rebuild.args[0]._steps.steps
    assert len(steps) == 4 + 1 + merge_passes(n)  # its chunk sort and merges
    assert trees[0].num_nodes == trees[1].num_nodes
    assert tree_arrays(trees[0]) == tree_arrays(trees[1])


def test_kernel_sort_build_replays_as_a_graph_from_its_second_run(monkeypatch):
    """All launches (the kdsl sort, no scan): run one by one, then captured once and
    replayed (a stand-in capture here; the CPU's own captures replay launch by launch),
    the tree always that of a build of its own."""
    counts = counting_capture(monkeypatch)
    monkeypatch.setattr(lbvh, "device_sort_on", lambda device: True)
    monkeypatch.setattr(lbvh, "graphs_on", lambda device: True)
    rng = np.random.default_rng(4)
    n = 1200
    lo = wp.array(rng.random((n, 3)).astype(np.float32), dtype=wp.vec3)
    hi = wp.array(lo.numpy() + 0.01, dtype=wp.vec3)
    tree = lbvh.build_lbvh(lo, hi, 2, None, 0, bottom_up=True, use_scan=False)
    assert counts == {"captures": 0, "replays": 0}
    for step in range(3):
        c = rng.random((n, 3)).astype(np.float32) * (step + 1)
        lo.assign(c)
        hi.assign(c + np.float32(0.02))
        tree.rebuild()
        assert counts == {"captures": 1, "replays": step + 1}
        recycle.clear()  # (a tree of its own, not the graphed build)
        own = lbvh.build_lbvh(lo, hi, 2, None, 0, bottom_up=True, use_scan=False)
        assert tree.num_nodes == own.num_nodes
        assert tree_arrays(tree) == tree_arrays(own)
