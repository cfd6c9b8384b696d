"""Nodes and triangles a closest-point query visits, per walk order, and what the
visiting costs a GPU warp: the counting behind docs/performance.md's mesh rows.

    python benchmarks/mesh_walk_counts.py [--tris 200000] [--queries 256]
        [--constructor lbvh|sah|median] [--leaf-size 4] [--tri-cost 4]

On the mesh benchmark's workload (``bench_geometry_mesh.workload``: the bumpy
cube-sphere, points uniform in the box 1.2 times the mesh's), a kdsl ``Mesh``'s BVH is
read back (its packed nodes, through the record a kernel sees) and three walks are
replayed here in NumPy, in float64, each finding the same closest distance:

- ``stackless``: kdsl's walk until ``bc12c0e``: a descent into the nearer child at each
  level gives a first bound, then a preorder walk jumping over the subtrees whose box
  lies beyond it;
- ``ordered``: Warp's order (``mesh_query_point_no_sign`` in warp/native/mesh.h, and
  kdsl's since ``bc12c0e``): a stack, both children's boxes tested at an inner node, the
  nearer visited first, a popped node tested again against the bound (kdsl's walk
  descends into the nearer child without the stack; the model counts Warp's loop);
- ``oracle``: the preorder walk given the final distance from the start: the fewest
  nodes and triangles any walk over this tree can test.

For each: the mean loop steps (a node whose box is tested; for Warp's order, a node
popped) and triangles tested per query (and triangles for the queries inside the mesh,
radius < 0.9, and outside, radius > 1.1). Then a model of a GPU warp of 32
consecutive queries, each thread's walk as a sequence of iterations, an iteration
costing 1 (a node) plus ``--tri-cost`` per triangle when it tests a leaf:

- ``if-if``: one node per iteration and the leaf's triangles in the same iteration;
  a warp runs as many iterations as its longest thread, each costing the most any of
  its threads pays in it;
- ``while-while``: each thread walks to its next leaf (the warp waits for the longest
  walk), then the warp tests leaves together (as many triangles as the largest leaf).

It is a count, not a timing: no memory traffic, no occupancy, Warp's walk replayed on
kdsl's tree (Warp builds its own). Queries are replayed in Python: a few hundred take
seconds.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import kdsl as wp
from kdsl.stdlib.bvh import BvhNode, BvhRecord

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_geometry_mesh import workload


@wp.kernel
def _copy_nodes(bvh: wp.uint64, nodes: wp.array(dtype=BvhNode), items: wp.array(dtype=int),
                root: wp.array(dtype=int)):  # fmt: skip
    i = wp.tid()
    rec = wp.object_record(bvh, BvhRecord)
    if i == 0:
        root[0] = rec.root
    if i < rec.nodes.shape[0]:
        nodes[i] = rec.nodes[i]
    if i < rec.items.shape[0]:
        items[i] = rec.items[i]


class Tree:
    """A BVH's packed nodes as NumPy arrays, the tree's faces' vertices, and the walks."""

    def __init__(self, mesh: wp.Mesh, pts: np.ndarray, faces: np.ndarray) -> None:
        slots, n_items = 2 * len(faces), len(faces)
        nodes = wp.zeros(slots, dtype=BvhNode)
        items = wp.zeros(n_items, dtype=int)
        root = wp.zeros(1, dtype=int)
        wp.launch(_copy_nodes, dim=slots, inputs=[mesh.bvh.id, nodes, items, root])
        self.root = int(root.numpy()[0])
        raw = nodes.numpy().view(np.int32).reshape(slots, 8)
        self.first, self.next = raw[:, 3], raw[:, 7]
        f32 = raw.view(np.float32)
        self.lo, self.hi = f32[:, 0:3].astype(np.float64), f32[:, 4:7].astype(np.float64)
        self.items = items.numpy()
        self.stop = self.skip(self.root)  # the node after the root's subtree
        tri = pts.astype(np.float64)[faces]
        self.a, self.b, self.c = tri[:, 0], tri[:, 1], tri[:, 2]

    def skip(self, n: int) -> int:
        return int(self.next[n]) if self.first[n] < 0 else n + 1

    def box(self, n: int, p: np.ndarray) -> float:
        g = np.maximum(np.maximum(self.lo[n] - p, p - self.hi[n]), 0.0)
        return float(g @ g)

    def tri(self, f: int, p: np.ndarray) -> float:
        """Squared distance from ``p`` to face ``f`` (Ericson's regions)."""
        a, b, c = self.a[f], self.b[f], self.c[f]
        ab, ac, ap = b - a, c - a, p - a
        d1, d2 = ab @ ap, ac @ ap
        if d1 <= 0 and d2 <= 0:
            return float(ap @ ap)
        bp = p - b
        d3, d4 = ab @ bp, ac @ bp
        if d3 >= 0 and d4 <= d3:
            return float(bp @ bp)
        vc = d1 * d4 - d3 * d2
        if vc <= 0 and d1 >= 0 and d3 <= 0:
            q = a + d1 / (d1 - d3) * ab
        else:
            cp = p - c
            d5, d6 = ab @ cp, ac @ cp
            vb = d5 * d2 - d1 * d6
            va = d3 * d6 - d5 * d4
            if d6 >= 0 and d5 <= d6:
                q = c
            elif vb <= 0 and d2 >= 0 and d6 <= 0:
                q = a + d2 / (d2 - d6) * ac
            elif va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:
                q = b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b)
            else:
                den = 1.0 / (va + vb + vc)
                q = a + ab * vb * den + ac * vc * den
        return float((q - p) @ (q - p))

    def leaf(self, n: int, p: np.ndarray, best: float, trace: list) -> float:
        k0, cnt = int(self.first[n]), int(self.next[n])
        for k in range(k0, k0 + cnt):
            best = min(best, self.tri(int(self.items[k]), p))
        trace.append(cnt)
        return best

    def walk_stackless(self, p: np.ndarray, best: float = np.inf) -> tuple[float, list]:
        trace: list[int] = []
        n = self.root
        while self.first[n] < 0:
            left = n + 1
            right = self.skip(left)
            trace += [0, 0]
            n = right if self.box(right, p) < self.box(left, p) else left
        return self.preorder(p, self.leaf(n, p, best, trace), trace, n, tighten=True)

    def preorder(self, p: np.ndarray, best: float, trace: list, seen: int,
                 tighten: bool) -> tuple[float, list]:  # fmt: skip
        """The stackless walk from the root, bounded by ``best`` (lowered by the faces
        it tests when ``tighten``), leaf ``seen`` left out."""
        n = self.root
        while n < self.stop:
            if self.box(n, p) <= best:
                if self.first[n] >= 0 and n != seen:
                    found = self.leaf(n, p, best, trace)
                    best = found if tighten else best
                else:
                    trace.append(0)
                n += 1
            else:
                trace.append(0)
                n = self.skip(n)
        return best, trace

    def walk_ordered(self, p: np.ndarray) -> tuple[float, list]:
        trace: list[int] = []
        best, stack = np.inf, [self.root]
        while stack:
            n = stack.pop()
            if self.box(n, p) > best:
                trace.append(0)
                continue
            if self.first[n] >= 0:
                best = self.leaf(n, p, best, trace)
                continue
            left = n + 1
            right = self.skip(left)
            dl, dr = self.box(left, p), self.box(right, p)
            trace.append(0)
            order = ((left, dl), (right, dr)) if dl >= dr else ((right, dr), (left, dl))
            for child, d in order:  # the nearer is pushed last
                if d < best:
                    stack.append(child)
        return best, trace

    def walk_oracle(self, p: np.ndarray, final: float) -> tuple[float, list]:
        return self.preorder(p, final, [], -1, tighten=False)


def if_if(traces: list[list[int]], tri_cost: float) -> float:
    """A warp's cost when every iteration visits one node and tests its leaf's faces."""
    steps = max(len(t) for t in traces)
    grid = np.zeros((len(traces), steps))
    for i, t in enumerate(traces):
        grid[i, : len(t)] = t
    return steps + tri_cost * grid.max(axis=0).sum()


def while_while(traces: list[list[int]], tri_cost: float) -> float:
    """A warp's cost when each thread walks to its next leaf, then the warp tests."""
    rounds = []
    for t in traces:
        r, gap = [], 0
        for x in t:
            gap += 1
            if x:
                r.append((gap, x))
                gap = 0
        if gap:
            r.append((gap, 0))
        rounds.append(r)
    cost = 0.0
    for k in range(max(len(r) for r in rounds)):
        live = [r[k] for r in rounds if k < len(r)]
        cost += max(g for g, _ in live) + tri_cost * max(x for _, x in live)
    return cost


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--tris", type=int, default=200_000)
    p.add_argument("--queries", type=int, default=256, help="a multiple of 32")
    p.add_argument("--constructor", default="lbvh")
    p.add_argument("--leaf-size", type=int, default=4)
    p.add_argument("--tri-cost", type=float, default=4.0)
    args = p.parse_args()
    data = workload(args.tris, args.queries)
    pts, faces = data["points"], data["faces"]
    mesh = wp.Mesh(wp.array(pts, dtype=wp.vec3), wp.array(faces.reshape(-1), dtype=wp.int32),
                   bvh_constructor=args.constructor, bvh_leaf_size=args.leaf_size)  # fmt: skip
    tree = Tree(mesh, pts, faces)
    qs = data["points_q"].astype(np.float64)
    radius = np.linalg.norm(qs, axis=1)
    traces: dict[str, list[list[int]]] = {"stackless": [], "ordered": [], "oracle": []}
    for q in qs:
        best, t = tree.walk_stackless(q)
        best_w, tw = tree.walk_ordered(q)
        if best_w != best:
            sys.exit(f"the walks disagree at {q}: {best} and {best_w}")
        traces["stackless"].append(t)
        traces["ordered"].append(tw)
        traces["oracle"].append(tree.walk_oracle(q, best)[1])
    print(f"{len(faces):,} faces, {args.constructor} tree, leaves of up to {args.leaf_size}, "
          f"{len(qs)} queries; per query:")  # fmt: skip
    print(f"{'walk':<10}{'steps':>8}{'tris':>8}{'tris in':>9}{'tris out':>10}"
          f"{'if-if/warp':>12}{'while-while/warp':>18}")  # fmt: skip
    for name, tr in traces.items():
        nodes = np.array([len(t) for t in tr])
        tris = np.array([sum(t) for t in tr])
        warps = range(0, len(tr) - len(tr) % 32, 32)
        ii = np.mean([if_if(tr[w : w + 32], args.tri_cost) for w in warps])
        ww = np.mean([while_while(tr[w : w + 32], args.tri_cost) for w in warps])
        print(f"{name:<10}{nodes.mean():8.1f}{tris.mean():8.1f}{tris[radius < 0.9].mean():9.1f}"
              f"{tris[radius > 1.1].mean():10.1f}{ii:12.0f}{ww:18.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
