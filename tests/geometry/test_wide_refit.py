"""The CPU mesh's refit in one pass over the wide tree's subtrees
(``kdsl.geometry.wide_collapse``'s cut, ``kdsl.geometry.wide_tree``'s ``_refit_tasks``
and ``_refit_top``): the cut covers every wide node, wide leaf and binary node once and
deals the tasks to the workers by faces; after the points moved, the vertex copy, the
binary tree's bounds (links untouched), the wide nodes' boxes and the leaves are what
each would be computed alone, for several trees and cuts (one task; a task a face, so
the top pass does most); a bad refit writes none of them."""

from __future__ import annotations

import numpy as np
import pytest

import kdsl as wp
import kdsl.geometry.wide_collapse as wide_collapse
import kdsl.geometry.wide_tree as wide_tree
from kdsl.errors import KdslTypeError
from kdsl.stdlib.mesh_wide import WideLeaf
from tests.geometry.mesh_reference import icosphere

V3 = wp.vec3
TREES = [("lbvh", 4), ("sah", 1), ("median", 3), ("lbvh", 2)]
#: (TASKS, MIN_TASK): the default cut, one task for the whole tree, a task per face.
CUTS = {"default": (wide_collapse.TASKS, wide_collapse.MIN_TASK), "one": (1, 1 << 30),
        "finest": (1 << 30, 1)}  # fmt: skip


@wp.kernel
def _leaves_alone(tri: wp.array(dtype=V3), items: wp.array(dtype=wp.int32),
                  spans: wp.array(dtype=wp.vec2i), out: wp.array(dtype=WideLeaf)):  # fmt: skip
    k = wp.tid()
    out[k] = wide_tree.leaf_from_tri(tri, items, spans[k])


def _mesh(pts, faces, constructor, leaf_size, cut, monkeypatch):
    monkeypatch.setitem(wide_tree.WIDE_TREE, "cpu", True)
    tasks, smallest = CUTS[cut]
    monkeypatch.setattr(wide_collapse, "TASKS", tasks)
    monkeypatch.setattr(wide_collapse, "MIN_TASK", smallest)
    return wp.Mesh(wp.array(pts, dtype=V3), wp.array(faces, dtype=wp.int32),
                   bvh_constructor=constructor, bvh_leaf_size=leaf_size)  # fmt: skip


def _exact_bounds(mesh, pts, faces):
    """Each binary node's exact box (children after parents in preorder: built in
    reverse), from the faces under it."""
    tree = mesh.bvh._tree
    m = tree.num_nodes
    first, count, skip = (a.numpy()[:m] for a in (tree.first, tree.count, tree.skip))
    corners = pts[faces[tree.items.numpy()]]  # (faces in item order, 3, 3)
    lo, hi = np.zeros((m, 3), np.float32), np.zeros((m, 3), np.float32)
    for n in reversed(range(m)):
        if first[n] >= 0:
            c = corners[first[n] : first[n] + count[n]].reshape(-1, 3)
            lo[n], hi[n] = c.min(0), c.max(0)
        else:
            r = skip[n + 1]
            lo[n], hi[n] = np.minimum(lo[n + 1], lo[r]), np.maximum(hi[n + 1], hi[r])
    return lo, hi


def _check_state(mesh, pts, faces):
    """The copy, the binary bounds, the wide boxes and the leaves against each computed
    alone from the current points."""
    items = mesh.bvh.item_order.numpy()
    np.testing.assert_array_equal(mesh._tree_points.tri.numpy().reshape(-1, 3, 3),
                                  pts[faces[items]])  # fmt: skip
    m = mesh.bvh._tree.num_nodes
    nodes = mesh.bvh._nodes.numpy()[:m]
    lo, hi = _exact_bounds(mesh, pts, faces)
    np.testing.assert_array_equal(nodes["lower"], lo)
    np.testing.assert_array_equal(nodes["upper"], hi)
    wide = mesh._wide
    for nd in wide.nodes.numpy():
        src = nd["src"]
        used = src >= 0
        for key, box in (("lo", lo), ("hi", hi)):
            for axis, name in enumerate("xyz"):
                got = nd[f"{key}_{name}"]
                np.testing.assert_array_equal(got[used], box[src[used], axis])
                assert np.isnan(got[~used]).all()
    alone = wp.empty(wide.leaves.shape[0], dtype=WideLeaf)
    wp.launch(_leaves_alone, dim=alone.shape[0],
              inputs=[mesh._tree_points.tri, mesh.bvh.item_order, wide._spans, alone])  # fmt: skip
    assert wide.leaves.numpy().tobytes() == alone.numpy().tobytes()


@pytest.mark.parametrize("cut", sorted(CUTS))
@pytest.mark.parametrize("constructor,leaf_size", TREES)
def test_the_cut_covers_the_trees_once(constructor, leaf_size, cut, monkeypatch):
    pts, faces = icosphere(3, bumps=0.05, seed=4)
    mesh = _mesh(pts, faces, constructor, leaf_size, cut, monkeypatch)
    w, c = mesh._wide, mesh._wide._cut
    tasks, trees = c.tasks.numpy(), c.trees.numpy()
    leaves = np.concatenate([np.arange(t[2], t[3]) for t in tasks])
    np.testing.assert_array_equal(leaves, np.arange(w.leaves.shape[0]))  # in order, once
    wide_nodes = np.concatenate([*(np.arange(t[0], t[1]) for t in tasks), c.top_wide.numpy()])
    np.testing.assert_array_equal(np.sort(wide_nodes), np.arange(w.nodes.shape[0]))
    binary = np.concatenate([*(np.arange(t[0], t[1]) for t in trees), c.tops.numpy()])
    np.testing.assert_array_equal(np.sort(binary), np.arange(mesh.bvh._tree.num_nodes))
    spans = w._spans.numpy()
    for t, tr in zip(tasks, trees):  # each task's face count is its leaves'
        assert tr[3] == spans[t[2] : t[3], 1].sum()
    assert trees[:, 3].sum() == len(faces) and (np.diff(trees[:, 2]) == trees[:-1, 3]).all()
    workers = c.workers.numpy()
    assert workers[0] == 0 and workers[-1] == len(tasks) and (np.diff(workers) >= 0).all()
    if cut == "one":
        assert len(tasks) == 1 and len(c.tops.numpy()) == 0
    if cut == "finest":  # every wide leaf a task of its own, every wide node above the cut
        assert len(tasks) == w.leaves.shape[0] and len(c.top_wide.numpy()) == w.nodes.shape[0]
    if cut == "default":  # the workers' shares of the faces are about equal
        share = np.add.reduceat(trees[:, 3], workers[:-1][np.diff(workers) > 0])
        assert share.max() <= len(faces) / wide_collapse.WORKERS + trees[:, 3].max()


@pytest.mark.parametrize("cut", sorted(CUTS))
@pytest.mark.parametrize("constructor,leaf_size", TREES)
def test_a_refit_writes_what_each_part_would_alone(constructor, leaf_size, cut, monkeypatch):
    pts, faces = icosphere(3, bumps=0.05, seed=5)
    mesh = _mesh(pts, faces, constructor, leaf_size, cut, monkeypatch)
    _check_state(mesh, pts, faces)  # as built
    rng = np.random.default_rng(1)
    for step in range(2):  # in place, then a new points array
        moved = (pts * rng.uniform(0.5, 1.5, (len(pts), 1)) + step).astype(np.float32)
        moved[7] = moved[faces[0, 0]]  # a sliver now: left out of its leaf
        if step == 0:
            mesh.points.assign(wp.array(moved, dtype=V3))
            mesh.refit()
        else:
            mesh.points = wp.array(moved, dtype=V3)
        _check_state(mesh, moved, faces)


def test_a_bad_refit_writes_nothing(monkeypatch):
    pts, faces = icosphere(2, bumps=0.05, seed=6)
    mesh = _mesh(pts, faces, "lbvh", 4, "default", monkeypatch)

    def state():
        return (mesh.bvh._nodes.numpy().tobytes(), mesh._tree_points.tri.numpy().tobytes(),
                mesh._wide.nodes.numpy().tobytes(), mesh._wide.leaves.numpy().tobytes())  # fmt: skip

    before = state()
    bad = pts * 2.0
    bad[3, 0] = np.nan
    mesh.points.assign(wp.array(bad, dtype=V3))
    with pytest.raises(KdslTypeError, match="point 3 is not finite"):
        mesh.refit()
    assert state() == before
    mesh.points.assign(wp.array(pts * 2.0, dtype=V3))
    mesh.refit()
    _check_state(mesh, (pts * 2.0).astype(np.float32), faces)
