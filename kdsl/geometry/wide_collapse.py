"""The collapse of a mesh's binary BVH into the 4-wide tree's topology, and its cut
into subtrees for the parallel refit (``kdsl.geometry.wide_tree``).

``collapse`` runs one kdsl kernel with one thread: from the root, depth first (so a
subtree's wide nodes, and its leaves, are numbered consecutively), each wide node takes
its binary node's two children and splits the one of largest surface area into its own
two, until it has four or only leaves are left, where a leaf is any binary subtree of
at most four faces whose faces are consecutive in the item order (so two small sibling
leaves share one wide leaf). It writes the topology (each wide node's ``child`` and
``src``, each wide leaf's faces) and, on the way, cuts the tree for the refit: the
first wide node met of at most ``target`` faces begins a **task** (its whole subtree:
consecutive wide nodes, consecutive wide leaves, and the binary nodes ``[b, end(b))``
of its binary node ``b``), and so does each wide leaf hanging from a wide node above
the cut. The binary nodes above the cut (each such wide node's binary node and the ones
it split) and the wide nodes above it are listed in the order met, parents first, for
the one thread that finishes a refit; and the tasks are dealt to ``WORKERS`` workers in
runs of about equal numbers of faces, so a refit launch of ``WORKERS`` threads is even
on the pool's equal chunks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from kdsl.frontend.api import func, inout, kernel, static
from kdsl.runtime.alloc import copy, empty
from kdsl.runtime.array import array
from kdsl.runtime.carve import carve
from kdsl.runtime.launch import launch
from kdsl.stdlib.bvh import BvhNode
from kdsl.types import float32, int32, vec2i, vec4, vec4i

#: The most faces a wide leaf holds (its four lanes).
LANES = 4
#: ``_collapse``'s status when a binary leaf holds more faces than a wide leaf.
REFUSED = 1
#: The refit's workers (threads of its launch), each given a run of tasks.
WORKERS = 64
#: About how many tasks a tree is cut into (a task holds at most ``faces / TASKS``
#: faces, and at least ``MIN_TASK`` may be asked for).
TASKS = 512
MIN_TASK = 64
#: The entries of ``_collapse``'s ``counts``.
_NODES, _LEAVES, _STATUS, _TASKS, _TOPS, _TOP_WIDE = range(6)


@func
def _end(nodes: array(dtype=BvhNode), n: int) -> int:
    """The node after the subtree of binary node ``n`` (preorder)."""
    nd = nodes[n]
    if nd.first >= 0:
        return n + 1
    return nd.next


@func
def _faces(nodes: array(dtype=BvhNode), n: int) -> int:
    """The number of faces under binary node ``n`` (its leftmost leaf's first position
    to its rightmost leaf's end: a subtree's items are consecutive)."""
    m = n
    while nodes[m].first < 0:
        m = m + 1
    lo = nodes[m].first
    m = n
    while nodes[m].first < 0:
        m = _end(nodes, m + 1)  # the right child
    return nodes[m].first + nodes[m].next - lo


@func
def _small(nodes: array(dtype=BvhNode), n: int) -> vec2i:
    """``(first, count)`` of the faces of binary node ``n``'s subtree when it holds at
    most ``LANES`` of them, at consecutive positions of the item order; count -1
    otherwise. Reads at most a few nodes: a subtree of more than ``2 LANES - 1`` nodes
    has more than ``LANES`` leaves (no node read), and the walk stops past ``LANES``
    faces."""
    end = _end(nodes, n)
    first = -1
    total = 0
    if end - n > 2 * LANES - 1:
        total = -1
    m = n
    while m < end and total >= 0:
        nd = nodes[m]
        if nd.first >= 0:
            if first < 0:
                first = nd.first
            if nd.first != first + total or total + nd.next > LANES:
                total = -1
            else:
                total = total + nd.next
        m = m + 1
    return vec2i(first, total)


@func
def _area(nodes: array(dtype=BvhNode), n: int) -> float:
    """Half the surface area of binary node ``n``'s box."""
    nd = nodes[n]
    e = nd.upper - nd.lower
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]


@func
def _candidate(
    nodes: array(dtype=BvhNode), n: int, at: int, kids: inout(vec4i), firsts: inout(vec4i),
    counts: inout(vec4i), areas: inout(vec4),
):  # fmt: skip
    """Binary node ``n`` as a wide node's child ``at``: a wide leaf (``_small``: its
    faces' first position and count) or a node (count -1, and its box's half area, to
    pick the next split)."""
    r = _small(nodes, n)
    kids[at] = n
    firsts[at] = r[0]
    counts[at] = r[1]
    areas[at] = float32(0.0)
    if r[1] < 0:
        areas[at] = _area(nodes, n)


@func
def _children(
    nodes: array(dtype=BvhNode), b: int, kids: inout(vec4i), firsts: inout(vec4i),
    counts: inout(vec4i), splits: inout(vec2i),
):  # fmt: skip
    """The (up to) four binary nodes under inner node ``b`` that become a wide node's
    children (``kids``, -1: an empty slot): ``b``'s two, then the largest (by area)
    that is not a wide leaf split into its two, until four or only wide leaves; with
    each wide leaf's faces (``firsts``, ``counts``; count -1 for a node) and the binary
    nodes split (``splits``, in order; -1: none)."""
    kids = vec4i(b + 1, _end(nodes, b + 1), -1, -1)
    splits = vec2i(-1, -1)
    areas = vec4(float32(0.0))
    for j in range(static(2)):
        _candidate(nodes, kids[j], j, kids, firsts, counts, areas)
    k = 2
    while k < LANES:
        pick = -1
        for j in range(static(LANES)):
            if j < k and counts[j] < 0 and (pick < 0 or areas[j] > areas[pick]):
                pick = j
        if pick < 0:
            k = LANES
        else:
            split = kids[pick]
            splits[k - 2] = split
            _candidate(nodes, split + 1, pick, kids, firsts, counts, areas)
            _candidate(nodes, _end(nodes, split + 1), k, kids, firsts, counts, areas)
            k = k + 1


@func
def _add_task(
    tasks: array(dtype=vec4i), trees: array(dtype=vec4i), t: int, w: int, leaf: int, b: int,
    end: int, at: int,
):  # fmt: skip
    """Open task ``t``: wide nodes and leaves from ``w`` and ``leaf`` (their ends written
    when it closes), binary nodes ``[b, end)``, its faces from ``at`` (the faces before
    it in task order; their count written when it closes)."""
    tasks[t] = vec4i(w, w, leaf, leaf)
    trees[t] = vec4i(b, end, at, 0)


@func
def _close_task(
    tasks: array(dtype=vec4i), trees: array(dtype=vec4i), t: int, w: int, leaf: int, at: int,
):  # fmt: skip
    """Close task ``t`` at wide node ``w`` and leaf ``leaf``, with ``at`` faces so far."""
    tk = tasks[t]
    tasks[t] = vec4i(tk[0], w, tk[2], leaf)
    tr = trees[t]
    trees[t] = vec4i(tr[0], tr[1], tr[2], at - tr[2])


@kernel
def _collapse(
    nodes: array(dtype=BvhNode), target: int32, stack: array(dtype=int32),
    parents: array(dtype=int32), child: array(dtype=vec4i), src: array(dtype=vec4i),
    spans: array(dtype=vec2i), tasks: array(dtype=vec4i), trees: array(dtype=vec4i),
    tops: array(dtype=int32), top_wide: array(dtype=int32), workers: array(dtype=int32),
    counts: array(dtype=int32),
):  # fmt: skip
    # One thread, depth first (a subtree's wide nodes and leaves are numbered
    # consecutively): binary node stack[t] becomes the next wide node, linked into
    # lane parents[t] % 4 of wide node parents[t] / 4 (-1: the root); writes child[w],
    # src[w] and each wide leaf's faces (spans: first position in the items, count);
    # the tasks (tasks: wide nodes [x, y), leaves [z, w); trees: binary nodes [x, y),
    # faces before, faces), the binary and the wide nodes above them (tops, top_wide),
    # the workers' first tasks (workers, WORKERS + 1 entries); counts = (wide nodes,
    # wide leaves, status, tasks, tops, top wide nodes).
    num_nodes = 0
    num_leaves = 0
    num_tasks = 0
    num_tops = 0
    num_top_wide = 0
    faces = 0
    status = 0
    open_at = -1  # the stack height under the open task's root (-1: none open)
    stack[0] = 0
    parents[0] = -1
    top = 1
    while top > 0:
        top = top - 1
        b = stack[top]
        w = num_nodes
        num_nodes = num_nodes + 1
        if open_at >= 0 and top < open_at:  # past the open task's subtree
            _close_task(tasks, trees, num_tasks - 1, w, num_leaves, faces)
            open_at = -1
        above = open_at < 0
        if above and _faces(nodes, b) <= target:
            _add_task(tasks, trees, num_tasks, w, num_leaves, b, _end(nodes, b), faces)
            num_tasks = num_tasks + 1
            open_at = top
            above = False
        up = parents[top]
        if up >= 0:
            link = child[up // LANES]
            link[up % LANES] = w
            child[up // LANES] = link
        kids = vec4i(b, -1, -1, -1)  # a root of at most four faces: one leaf under the root
        r = _small(nodes, b)
        firsts = vec4i(r[0], 0, 0, 0)
        sizes = vec4i(r[1], 0, 0, 0)
        splits = vec2i(-1, -1)
        if r[1] < 0:
            if nodes[b].first >= 0:
                status = REFUSED  # a binary leaf of more faces than a wide leaf's lanes
            else:
                _children(nodes, b, kids, firsts, sizes, splits)
        if above:
            top_wide[num_top_wide] = w
            num_top_wide = num_top_wide + 1
            if r[1] < 0:
                tops[num_tops] = b
                num_tops = num_tops + 1
                for j in range(static(2)):
                    if splits[j] >= 0:
                        tops[num_tops] = splits[j]
                        num_tops = num_tops + 1
        links = vec4i(-1)
        for j in range(static(LANES)):
            n = kids[j]
            if n >= 0:
                if sizes[j] >= 0:
                    if above:  # a leaf under a node above the cut: a task of its own
                        _add_task(tasks, trees, num_tasks, num_nodes, num_leaves, n,
                                  _end(nodes, n), faces)  # fmt: skip
                        _close_task(tasks, trees, num_tasks, num_nodes, num_leaves + 1,
                                    faces + sizes[j])  # fmt: skip
                        num_tasks = num_tasks + 1
                    spans[num_leaves] = vec2i(firsts[j], sizes[j])
                    links[j] = -num_leaves - 1
                    num_leaves = num_leaves + 1
                    faces = faces + sizes[j]
                elif nodes[n].first >= 0:
                    status = REFUSED
        for jj in range(static(LANES)):  # the wide nodes below, lane 0 on top
            j = LANES - 1 - jj
            n = kids[j]
            if n >= 0 and sizes[j] < 0 and nodes[n].first < 0:
                stack[top] = n
                parents[top] = w * LANES + j
                top = top + 1
        child[w] = links
        src[w] = kids
        if status != 0:
            top = 0  # (stop: the mesh walks its binary tree)
    if open_at >= 0:
        _close_task(tasks, trees, num_tasks - 1, num_nodes, num_leaves, faces)
    # The workers: worker k takes the tasks that begin in its share of the faces.
    k = 0
    for t in range(num_tasks):
        own = (trees[t][2] * WORKERS) // max(faces, 1)
        while k <= own:
            workers[k] = t
            k = k + 1
    while k <= WORKERS:
        workers[k] = num_tasks
        k = k + 1
    counts[_NODES] = num_nodes
    counts[_LEAVES] = num_leaves
    counts[_STATUS] = status
    counts[_TASKS] = num_tasks
    counts[_TOPS] = num_tops
    counts[_TOP_WIDE] = num_top_wide


@dataclass
class Collapsed:
    """``collapse``'s result on the tree's device: the wide nodes' links ``child`` and
    ``src`` (views of the collapse's scratch, for the first fill), and, kept (views of
    one block), the leaves' ``spans``, the cut for the refit (``tasks``, ``trees``,
    ``tops``, ``top_wide``, ``workers``), and ``status`` (``REFUSED``: no wide tree)."""

    child: array | None
    src: array | None
    spans: array
    tasks: array
    trees: array
    tops: array
    top_wide: array
    workers: array
    done: array
    status: int


def _blocks(words: list[tuple[Any, int]], device) -> list[array]:
    """Views of one new int32 block: one per ``(dtype, count)`` (dtype of 1, 2 or 4
    int32 words), laid one after the other."""
    sizes = [n * _WORDS[t] for t, n in words]
    block = empty(max(sum(sizes), 1), dtype=int32, device=device)
    at, parts = 0, []
    for (t, n), size in zip(words, sizes):
        parts.append((4 * at, t, n))
        at += size
    return carve(block, parts)


#: int32 words of the collapse's element types.
_WORDS = {int32: 1, vec2i: 2, vec4i: 4}


def collapse(nodes: array, num_tris: int, device) -> Collapsed:
    """Collapse the binary tree of packed ``nodes`` (over ``num_tris`` faces, bounds
    current) on ``device``: one launch, one read back of its counts, the scratch one
    allocation and what is kept another."""
    cap = max(num_tris, 1)  # at most one wide node, one leaf, one task a face
    (child, src, tasks, trees, spans, stack, parents, tops, top_wide, workers,
     counts) = _blocks([(vec4i, cap)] * 4 + [(vec2i, cap)] + [(int32, cap)] * 4
                       + [(int32, WORKERS + 1), (int32, 6)], device)  # fmt: skip
    got = [0] * 6
    if num_tris > 0:
        target = max(MIN_TASK, num_tris // TASKS)
        launch(_collapse, dim=1, device=device,
               inputs=[nodes, target, stack, parents, child, src, spans, tasks, trees, tops,
                       top_wide, workers, counts])  # fmt: skip
        got = [int(x) for x in counts.numpy()]
    if got[_STATUS] != 0:
        got = [0, 0, got[_STATUS], 0, 0, 0]
    if got[_TASKS] == 0:
        workers.zero_()
    n, m, t = got[_NODES], got[_LEAVES], got[_TASKS]
    parts = [(spans, vec2i, m), (tasks, vec4i, t), (trees, vec4i, t), (tops, int32, got[_TOPS]),
             (top_wide, int32, got[_TOP_WIDE]), (workers, int32, WORKERS + 1),
             (None, int32, 1)]  # fmt: skip
    kept = _blocks([(dtype, k) for _, dtype, k in parts], device)
    for dst, (a, _, k) in zip(kept, parts):
        if a is not None and k:
            copy(dst, a, count=k)
    kept[-1].zero_()
    return Collapsed(child[:n], src[:n], *kept, got[_STATUS])
