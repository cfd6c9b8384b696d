"""Variants of the closest-ray-hit walk (``mesh_query_ray``'s search), compiled side by
side as user ``@func`` code, for A/B timing against the standard library and Warp.

    python benchmarks/mesh_ray_walks.py [--tris 200000] [--rays 1000000] [--reps 20]
        [--device cuda:0] [--variants payload,lib_r64] [--no-warp] [--json PATH]

Each variant is a kernel that answers ``mesh_query_ray(mesh, start, dir, 1e6)`` for one
ray per thread on the bumpy cube-sphere of ``bench_geometry_mesh.workload`` and writes
the face and ``t``; ``lib`` (always run) calls the library. The variants (``VARIANTS``):

- ``payload``: Warp's stack discipline on nodes whose ``first`` holds minus the right
  child's index (``right_linked``, built here on the host from the packed nodes): an
  inner node names both children, so their two loads are independent, and a stack
  entry carries a node's payload (children, or a leaf's range), so a pop loads no node;
- ``*_r64``: the kernel compiled with ``cuda_max_registers=64`` (4 blocks of 256 threads
  per H200 multiprocessor instead of 3).

Session 11 (docs/performance.md, "Mesh rays on the GPU, session 11") also ran the
session-10 search filled and not (``old_lib``, ``git show
f8cbe2b:benchmarks/mesh_ray_walks.py``) and copies without the stackless fallback, an
unpadded slab test, kept pops, global loads and the left child loaded a level ahead
(``git show 6850bcd:benchmarks/mesh_ray_walks.py``).
Every kernel but ``lib`` recomputes the hit after the search as the library does (so
the times compare searches). Times are the minimum over ``--reps`` launches after a
warm-up. Answers are checked: every variant's faces and ``t`` must equal the library's
exactly (same tie rule), and the library's hit/miss must agree with Warp's on all but
``RAY_DISAGREEMENT`` of the rays. The table prints ms per launch and the ratio to
Warp's time (> 1: faster than Warp).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import kdsl as wp
from kdsl.stdlib.bvh import BvhNode, BvhRecord
from kdsl.stdlib.mesh import MeshRecord
from kdsl.stdlib.mesh_primitives import (
    RayShear,
    intersect_ray_triangle,
    ray_box_enter,
    ray_shear,
    safe_inverse,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_geometry_mesh import MAX_T, RAY_DISAGREEMENT, mesh_kernels, workload

STACK = 32
#: The variants: name -> ``variant_kernel``'s keywords (its defaults: the library's walk).
VARIANTS = {
    "payload": {"walk": "payload"},
    "lib_r64": {"walk": "lib", "regs": 64},
}


@wp.struct
class Hit:
    t: wp.float32
    face: wp.int32
    slot: wp.int32


@wp.func
def leaf_hits(rec: MeshRecord, bvh: BvhRecord, first: int, count: int, shear: RayShear,
              start: wp.vec3, best: Hit) -> Hit:  # fmt: skip
    hit = best
    for k in range(first, first + count):
        h = intersect_ray_triangle(
            shear, start, rec.tri[k * 3], rec.tri[k * 3 + 1], rec.tri[k * 3 + 2]
        )
        t = h[0]
        if t >= 0.0 and t <= hit.t:
            f = bvh.items[k]
            if t < hit.t or (hit.slot >= 0 and f < hit.face):
                hit.t = t
                hit.face = f
                hit.slot = k
    return hit


@wp.func
def push(sa: wp.array(dtype=wp.int32), sb: wp.array(dtype=wp.int32),
         st: wp.array(dtype=wp.float32), count: int, a: int, b: int, t: float) -> int:  # fmt: skip
    """Payload ``(a, b)`` entered at ``t`` onto the stack of ``count`` entries: the new
    count (``STACK + 1``: full, the entry is lost and the walk answers -2)."""
    if count < STACK:
        sa[count] = a
        sb[count] = b
        st[count] = t
        return count + 1
    return STACK + 1


def _payload_walk():
    """Warp's discipline on right-linked nodes (``alt``, ``right_linked``): a node is
    carried as its payload ``(a, b)``: an inner node's children ``(a, -b)``, a leaf's
    items ``[a, a + b)``; a stack entry is a payload and its entry ``t``. Both children
    of a level load at once; a pop loads nothing."""

    @wp.func
    def walk(id: wp.uint64, alt: wp.array(dtype=BvhNode), start: wp.vec3, dir: wp.vec3,
             max_t: float) -> int:  # fmt: skip
        rec = wp.object_record(id, MeshRecord)
        bvh = wp.object_record(rec.bvh, BvhRecord)
        shear = ray_shear(dir)
        inv = wp.vec3(safe_inverse(dir[0]), safe_inverse(dir[1]), safe_inverse(dir[2]))
        hit = Hit()
        hit.t = max_t
        hit.face = -1
        hit.slot = -1
        sa = wp.ext.empty(STACK, dtype=wp.int32)
        sb = wp.ext.empty(STACK, dtype=wp.int32)
        st = wp.ext.empty(STACK, dtype=wp.float32)
        count = 0
        lost = False
        root = bvh.root
        active = False
        a = 0
        b = 0
        if root >= 0:
            nd = alt[root]
            active = ray_box_enter(nd.lower, nd.upper, start, inv) <= hit.t
            a = nd.first
            b = nd.next
            if nd.first < 0:
                a = root + 1
                b = nd.first
        while active:
            descend = b < 0
            while descend:  # an inner node: both children, loaded independently
                left = alt[a]
                right = alt[-b]
                t_l = ray_box_enter(left.lower, left.upper, start, inv)
                t_r = ray_box_enter(right.lower, right.upper, start, inv)
                l_in = t_l <= hit.t
                r_in = t_r <= hit.t
                # payloads of the two children
                la = left.first
                lb = left.next
                if left.first < 0:
                    la = a + 1
                    lb = left.first
                ra = right.first
                rb = right.next
                if right.first < 0:
                    ra = -b + 1
                    rb = right.first
                if r_in and (not l_in or t_r < t_l):  # the right child first
                    if l_in:
                        count = push(sa, sb, st, count, la, lb, t_l)
                    a = ra
                    b = rb
                elif l_in:
                    if r_in:
                        count = push(sa, sb, st, count, ra, rb, t_r)
                    a = la
                    b = lb
                else:
                    b = 0  # both missed: nothing to test
                if count > STACK:
                    lost = True
                    count = STACK
                descend = b < 0
            if b >= 0:  # at a leaf (b = 0: both children missed): its faces, then a pop
                hit = leaf_hits(rec, bvh, a, b, shear, start, hit)
                active = False
                while count > 0 and not active:
                    count = count - 1
                    if st[count] <= hit.t:
                        a = sa[count]
                        b = sb[count]
                        active = True
        if lost:
            return -2
        return hit.slot

    return walk


@wp.func
def finish(id: wp.uint64, slot: int, start: wp.vec3, dir: wp.vec3) -> wp.vec2:
    """The library's tail after the search: the hit recomputed from its slot (``t``,
    face as a float; face -1 for a miss)."""
    if slot < 0:
        return wp.vec2(0.0, float(slot))
    rec = wp.object_record(id, MeshRecord)
    a = rec.tri[slot * 3]
    b = rec.tri[slot * 3 + 1]
    c = rec.tri[slot * 3 + 2]
    h = intersect_ray_triangle(ray_shear(dir), start, a, b, c)
    face = wp.object_record(rec.bvh, BvhRecord).items[slot]
    return wp.vec2(h[0], float(face))


def variant_kernel(walk: str, regs: int | None = None):
    """The kernel of one variant: ``face[i]``, ``t[i]`` of ray ``i``. ``walk``: "lib"
    (``mesh_query_ray``) or "payload"; ``regs``: the kernel option
    ``cuda_max_registers``."""
    options = {} if regs is None else {"cuda_max_registers": regs}
    if walk == "lib":  # the mesh benchmark's ray kernel (one source for kdsl and Warp)
        return wp.kernel(mesh_kernels(wp)[1].fn, enable_backward=False, **options)
    search = _payload_walk()

    @wp.kernel(enable_backward=False, **options)
    def rays(mesh: wp.uint64, alt: wp.array(dtype=BvhNode), start: wp.array(dtype=wp.vec3),
             d: wp.array(dtype=wp.vec3), face: wp.array(dtype=wp.int32),
             t: wp.array(dtype=float)):  # fmt: skip
        i = wp.tid()
        slot = search(mesh, alt, start[i], d[i], MAX_T)
        r = finish(mesh, slot, start[i], d[i])
        face[i] = int(r[1])
        t[i] = r[0]

    return rays


@wp.kernel(enable_backward=False)
def _node_count(mesh: wp.uint64, out: wp.array(dtype=wp.int32)):
    rec = wp.object_record(mesh, MeshRecord)
    out[0] = wp.object_record(rec.bvh, BvhRecord).nodes.shape[0]


@wp.kernel(enable_backward=False)
def _copy_nodes(mesh: wp.uint64, out: wp.array(dtype=BvhNode)):
    i = wp.tid()
    rec = wp.object_record(mesh, MeshRecord)
    out[i] = wp.object_record(rec.bvh, BvhRecord).nodes[i]


def packed_nodes(mesh: wp.Mesh, dev: str) -> np.ndarray:
    """The packed nodes of ``mesh``'s BVH, read through its record (a NumPy structured
    array)."""
    n = wp.zeros(1, dtype=wp.int32, device=dev)
    wp.launch(_node_count, 1, [mesh.id, n], device=dev)
    out = wp.zeros(int(n.numpy()[0]), dtype=BvhNode, device=dev)
    wp.launch(_copy_nodes, out.shape[0], [mesh.id, out], device=dev)
    return out.numpy()


def right_linked(nodes: np.ndarray) -> np.ndarray:
    """A copy of packed nodes (a ``BvhNode`` structured array) whose inner nodes'
    ``first`` is minus their right child's index (the left child is the next node)."""
    out = nodes.copy()
    first, nxt = nodes["first"], nodes["next"]
    inner = np.flatnonzero(first == -1)
    left = inner + 1
    right = np.where(first[left] >= 0, left + 1, nxt[left])
    out["first"][inner] = -right
    return out


def _time(fn, reps: int, sync) -> float:
    fn()
    sync()
    best = float("inf")
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        sync()
        best = min(best, time.perf_counter() - t0)
    return best


def _warp_side(data: dict, device: str, reps: int):
    import warp

    warp.config.quiet = True
    warp.init()

    wrays = mesh_kernels(warp)[1]

    pts = warp.array(data["points"], dtype=warp.vec3, device=device)
    idx = warp.array(data["faces"].reshape(-1), dtype=warp.int32, device=device)
    mesh = warp.Mesh(pts, idx)
    n = len(data["ray_start"])
    s = warp.array(data["ray_start"], dtype=warp.vec3, device=device)
    d = warp.array(data["ray_dir"], dtype=warp.vec3, device=device)
    face = warp.zeros(n, dtype=warp.int32, device=device)
    t = warp.zeros(n, dtype=float, device=device)

    def run():
        warp.launch(wrays, n, [mesh.id, s, d, face, t], device=device)

    secs = _time(run, reps, lambda: warp.synchronize_device(device))
    return secs, face.numpy(), t.numpy(), mesh


def main(argv: list[str] | None = None) -> int:
    """Run the variants (and Warp), print the table, check the answers; exit status 1
    when an answer disagrees."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tris", type=int, default=200_000)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--no-warp", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    dev = args.device
    data = workload(args.tris, args.rays)
    n = len(data["ray_start"])
    mesh = wp.Mesh(wp.array(data["points"], dtype=wp.vec3, device=dev),
                   wp.array(data["faces"].reshape(-1), dtype=wp.int32, device=dev))  # fmt: skip
    alt = wp.array(right_linked(packed_nodes(mesh, dev)), dtype=BvhNode, device=dev)
    s = wp.array(data["ray_start"], dtype=wp.vec3, device=dev)
    d = wp.array(data["ray_dir"], dtype=wp.vec3, device=dev)
    rows: list[dict] = []
    answers: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    warp_row = None
    if not args.no_warp:
        secs, wface, wt, _keep = _warp_side(data, dev, args.reps)
        warp_row = {"variant": "warp", "ms": secs * 1e3}
        answers["warp"] = (wface, wt)
    kernels = {"lib": variant_kernel("lib")}
    for name in [v for v in args.variants.split(",") if v]:
        kernels[name] = variant_kernel(**VARIANTS[name])
    for name, k in kernels.items():
        face = wp.zeros(n, dtype=wp.int32, device=dev)
        t = wp.zeros(n, dtype=float, device=dev)

        def run(k=k, face=face, t=t):
            args = (
                [mesh.id, s, d, face, t]
                if k.arg_names[1] == "start"
                else [mesh.id, alt, s, d, face, t]
            )
            wp.launch(k, n, args, device=dev)

        secs = _time(run, args.reps, lambda: wp.synchronize_device(dev))
        answers[name] = (face.numpy(), t.numpy())
        rows.append({"variant": name, "ms": secs * 1e3})
    ok = True
    lf, lt = answers["lib"]
    for row in rows:
        f, t = answers[row["variant"]]
        row["face_diff"] = int((f != lf).sum())
        row["t_diff"] = int(((t != lt) & (lf >= 0)).sum())
        ok &= row["face_diff"] == 0 and row["t_diff"] == 0
    if warp_row is not None:
        wf, wt = answers["warp"]
        warp_row["face_diff"] = int(((wf >= 0) != (lf >= 0)).sum())
        both = (wf >= 0) & (lf >= 0)
        warp_row["t_diff"] = int((np.abs(wt - lt) > 1e-5 * np.maximum(1, np.abs(lt)))[both].sum())
        ok &= warp_row["face_diff"] <= RAY_DISAGREEMENT * n
        rows.insert(0, warp_row)
        for row in rows:
            row["vs_warp"] = warp_row["ms"] / row["ms"]
    print(f"{n} rays, {len(data['faces'])} triangles, {dev}, min of {args.reps} launches")
    print(f"{'variant':<26}{'ms':>8}{'x Warp':>8}{'face diff':>11}{'t diff':>8}")
    for r in rows:
        print(f"{r['variant']:<26}{r['ms']:8.3f}{r.get('vs_warp', float('nan')):8.2f}"
              f"{r['face_diff']:11d}{r['t_diff']:8d}")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "n": n}, indent=1))
    if not ok:
        print("ANSWERS DISAGREE")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
