"""Builds of collected geometry objects taken by the next object of the same shape
(``kdsl.geometry.recycle``): the bin's filing (identity of inputs, equal shapes, the
newest first, a bounded count, unusable builds dropped) and the lbvh builds a fresh
``Bvh`` takes: the same arrays, the same tree bit for bit as a build of its own, the
collected BVH's id freed; never a live BVH's build, another stream's, or a build cut
short."""

from __future__ import annotations

import gc

import numpy as np
import pytest

import kdsl as wp
from kdsl.geometry import lbvh, mesh_refit, recycle
from kdsl.runtime.objects import owner_of

cuda = pytest.mark.skipif(not wp.is_cuda_available(), reason="no GPU")
DEVICES = ["cpu", pytest.param("cuda:0", marks=cuda)]


class Owner:
    """A collectable owner of a build."""


def test_bin_files_by_identity_and_shape_newest_first():
    b = recycle.RecycleBin(2)
    x, y = np.zeros(3), np.zeros(3)  # equal values, two objects
    owners = [Owner() for _ in range(3)]
    b.keep_when_collected(owners[0], (x,), (3, 1), "first", lambda _: True)
    b.keep_when_collected(owners[1], (x,), (3, 1), "second", lambda _: True)
    b.keep_when_collected(owners[2], (y,), (3, 1), "other", lambda _: True)
    assert b.take((x,), (3, 1)) is None  # nothing until an owner is collected
    del owners[0]
    del owners[0]
    assert b.take((y,), (3, 1)) is None  # another object, equal or not
    assert b.take((x,), (3, 2)) is None  # another shape
    assert b.take((x,), (3, 1)) == "second"  # the newest first, then gone
    assert b.take((x,), (3, 1)) == "first"
    assert b.take((x,), (3, 1)) is None


def test_bin_keeps_its_capacity_and_only_usable_builds():
    b = recycle.RecycleBin(2)
    x = object()
    for name in ("a", "b", "c"):
        b.keep_when_collected(Owner(), (x,), (), name, lambda _: True)  # collected at once
    assert len(b) == 2  # "a", the oldest, went
    b.keep_when_collected(Owner(), (x,), (), "cut short", lambda _: False)
    assert len(b) == 2
    assert [b.take((x,), ()), b.take((x,), ()), b.take((x,), ())] == ["c", "b", None]
    b.keep_when_collected(Owner(), (x,), (), "d", lambda _: True)
    recycle.clear()
    assert len(b) == 0


def boxes(seed: int, n: int, device: str):
    rng = np.random.default_rng(seed)
    c = rng.random((n, 3)).astype(np.float32)
    lo = wp.array(c - np.float32(0.01), dtype=wp.vec3, device=device)
    hi = wp.array(c + np.float32(0.01), dtype=wp.vec3, device=device)
    return lo, hi


def tree_bytes(bvh) -> tuple:
    t = bvh._tree
    return (bvh._nodes.numpy().tobytes(), t.items.numpy().tobytes(), t.skip.numpy().tobytes(),
            t.first.numpy().tobytes(), t.count.numpy().tobytes(), t.parent.numpy().tobytes(),
            t.num_nodes)  # fmt: skip


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_fresh_bvh_takes_a_collected_ones_build_and_gives_the_same_tree(device, leaf_size):
    recycle.clear()
    lo, hi = boxes(1, 2000, device)
    first = wp.Bvh(lo, hi, constructor="lbvh", leaf_size=leaf_size)
    ptr, old_id = first._nodes.ptr, first.id
    del first
    assert owner_of(old_id) is None  # the collected BVH's id is freed as before
    c = np.random.default_rng(2).random((2000, 3)).astype(np.float32)  # other values
    lo.assign(c - np.float32(0.02))
    hi.assign(c + np.float32(0.02))
    again = wp.Bvh(lo, hi, constructor="lbvh", leaf_size=leaf_size)
    assert again._nodes.ptr == ptr  # the collected BVH's block
    got = tree_bytes(again)
    recycle.clear()
    own = wp.Bvh(lo, hi, constructor="lbvh", leaf_size=leaf_size)
    assert own._nodes.ptr != ptr
    assert got == tree_bytes(own)
    again.rebuild()  # the taken build rebuilds as its own would
    assert tree_bytes(again) == got


@pytest.mark.parametrize("device", DEVICES)
def test_live_bvh_or_other_boxes_keep_their_builds_apart(device):
    recycle.clear()
    lo, hi = boxes(3, 1000, device)
    live = wp.Bvh(lo, hi, constructor="lbvh")
    second = wp.Bvh(lo, hi, constructor="lbvh")
    assert second._nodes.ptr != live._nodes.ptr  # the live BVH's build stays its own
    ptr = second._nodes.ptr
    del second
    lo2, hi2 = boxes(3, 1000, device)  # the same values, other arrays
    other = wp.Bvh(lo2, hi2, constructor="lbvh")
    wider = wp.Bvh(lo, hi, constructor="lbvh", leaf_size=2)
    assert ptr not in (other._nodes.ptr, wider._nodes.ptr)
    again = wp.Bvh(lo, hi, constructor="lbvh")
    assert again._nodes.ptr == ptr
    assert tree_bytes(again) == tree_bytes(live)


def test_a_build_cut_short_is_not_kept(monkeypatch):
    recycle.clear()
    lo, hi = boxes(4, 500, "cpu")
    bvh = wp.Bvh(lo, hi, constructor="lbvh")
    build = bvh._tree.rebuild.args[0]

    def broken() -> None:
        raise RuntimeError("cut short")

    monkeypatch.setattr(build._steps, "steps", [*build._steps.steps[:2], broken])
    with pytest.raises(RuntimeError, match="cut short"):
        bvh.rebuild()
    del bvh
    gc.collect()
    assert len(lbvh.BUILDS) == 0


@cuda
def test_a_build_on_another_stream_is_not_taken():
    recycle.clear()
    lo, hi = boxes(5, 1000, "cuda:0")
    first = wp.Bvh(lo, hi, constructor="lbvh")
    ptr = first._nodes.ptr
    del first
    with wp.ScopedStream(wp.Stream("cuda:0")):
        other = wp.Bvh(lo, hi, constructor="lbvh")
        assert other._nodes.ptr != ptr


def grid_mesh(device: str, cells: int = 12):
    """A bumpy height field of ``2 * cells**2`` triangles: (points, indices) arrays."""
    g = np.arange(cells + 1, dtype=np.float32) / cells
    x, y = np.meshgrid(g, g, indexing="ij")
    z = 0.1 * np.sin(7 * x) * np.cos(5 * y)
    pts = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)
    v = np.arange((cells + 1) ** 2).reshape(cells + 1, cells + 1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[:-1, 1:], v[1:, 1:]
    faces = np.concatenate([np.stack([a, b, d], -1), np.stack([a, d, c], -1)]).reshape(-1, 3)
    return (wp.array(pts, dtype=wp.vec3, device=device),
            wp.array(faces.astype(np.int32).ravel(), dtype=wp.int32, device=device))  # fmt: skip


def mesh_state(mesh) -> tuple:
    return (*tree_bytes(mesh.bvh), mesh._faces.lowers.numpy().tobytes(),
            mesh._faces.edge_sum.numpy().tobytes())  # fmt: skip


@pytest.mark.parametrize("device", DEVICES)
def test_fresh_mesh_takes_a_collected_ones_face_boxes_and_bvh_build(device):
    recycle.clear()
    points, indices = grid_mesh(device)
    first = wp.Mesh(points, indices)
    ptrs, old_id = (first._faces.lowers.ptr, first.bvh._nodes.ptr), first.id
    del first
    assert owner_of(old_id) is None
    points.assign(points.numpy() * np.float32(1.5))  # moved: the new mesh sees the new points
    again = wp.Mesh(points, indices)
    assert (again._faces.lowers.ptr, again.bvh._nodes.ptr) == ptrs
    got = mesh_state(again)
    recycle.clear()
    own = wp.Mesh(points, indices)
    assert own._faces.lowers.ptr != ptrs[0]
    assert got == mesh_state(own)


def test_a_mesh_refused_for_a_bad_index_files_nothing():
    recycle.clear()
    points, indices = grid_mesh("cpu", 4)
    bad = wp.array(np.where(indices.numpy() == 3, 999, indices.numpy()).astype(np.int32))
    with pytest.raises(wp.errors.KdslTypeError, match="out of range"):
        wp.Mesh(points, bad)
    gc.collect()
    assert len(mesh_refit.FACE_BOXES) == 0  # refused before its BVH was made: not filed


@pytest.mark.parametrize("device", DEVICES)
def test_a_kept_bvh_keeps_its_collected_meshs_face_boxes(device):
    recycle.clear()
    points, indices = grid_mesh(device)
    mesh = wp.Mesh(points, indices)
    bvh, faces = mesh.bvh, mesh._faces
    before = tree_bytes(bvh)
    del mesh  # the BVH still reads the face boxes: they stay its own
    other = wp.Mesh(wp.array(points.numpy() * np.float32(3.0), dtype=wp.vec3, device=device),
                    indices)  # fmt: skip
    assert other._faces is not faces
    bvh.refit()
    assert tree_bytes(bvh) == before
    del bvh
    again = wp.Mesh(points, indices)
    assert again._faces is faces  # once the BVH is collected
