"""Project points onto a triangle mesh (the seeds' ``project`` kernel).

    python examples/mesh_project.py [MESH_FILE] [--points 100000] [--device cpu]

``MESH_FILE`` is any OBJ, PLY or STL file ``trimesh`` reads (``pip install
kdsl[geometry]``); without trimesh or without a file, the example projects onto a
generated "bumpy cube-sphere" (``bumpy_cube_sphere``), the mesh of the geometry
benchmark. Random points around the mesh go to their closest point on it; the example
prints how far they moved and checks that every point landed on its face's plane.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

import kdsl as wp


@wp.kernel
def project(positions: wp.array(dtype=wp.vec3), mesh: wp.uint64,
            output_pos: wp.array(dtype=wp.vec3), output_face: wp.array(dtype=int)):  # fmt: skip
    tid = wp.tid()
    x = wp.load(positions, tid)
    face_index = int(0)  # noqa: UP018, RUF046 - the seed's spelling (Warp's dynamic variables)
    face_u = float(0.0)  # noqa: UP018
    face_v = float(0.0)  # noqa: UP018
    sign = float(0.0)  # noqa: UP018
    max_dist = 2.0
    if wp.mesh_query_point(mesh, x, max_dist, sign, face_index, face_u, face_v):
        p = wp.mesh_eval_position(mesh, face_index, face_u, face_v)
        output_pos[tid] = p
        output_face[tid] = face_index


def bumpy_cube_sphere(cells: int = 129, bump: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A closed, outward-wound mesh of ``12 * cells**2`` triangles: each face of a cube
    cut into ``cells x cells`` squares (two triangles each), its vertices projected to
    the unit sphere and moved along their radius by ``bump * sin(6x) sin(6y) sin(6z)``.
    Returns points float32 ``(n, 3)`` and faces int32 ``(m, 3)``."""
    g = np.arange(cells + 1)
    i, j = np.meshgrid(g, g, indexing="ij")
    lattice, faces = [], []
    # Per cube face: the axis it is normal to, its side, and the in-plane axes ordered
    # so the triangles wind counter-clockwise seen from outside.
    for axis in range(3):
        for side in (0, cells):
            u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
            if side == 0:
                u_ax, v_ax = v_ax, u_ax
            grid = np.zeros((cells + 1, cells + 1, 3), np.int64)
            grid[..., axis] = side
            grid[..., u_ax] = i
            grid[..., v_ax] = j
            base = sum(len(x) for x in lattice)
            lattice.append(grid.reshape(-1, 3))
            k = base + i[:-1, :-1] * (cells + 1) + j[:-1, :-1]
            a, b, c, d = k, k + cells + 1, k + cells + 2, k + 1
            quad = np.stack([a, b, c, a, c, d], axis=-1).reshape(-1, 3)
            faces.append(quad)
    lattice = np.concatenate(lattice)
    # Cube edges and corners appear on several faces: merge the copies.
    unique, inverse = np.unique(lattice, axis=0, return_inverse=True)
    tris = inverse.reshape(-1)[np.concatenate(faces)]
    p = unique.astype(np.float64) / cells * 2.0 - 1.0
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    p *= 1.0 + bump * np.prod(np.sin(6.0 * p), axis=1, keepdims=True)
    return p.astype(np.float32), tris.astype(np.int32)


def load_mesh(path: str | None, cells: int = 129) -> tuple[np.ndarray, np.ndarray, str]:
    """Points and faces of the mesh file at ``path`` through trimesh, or the generated
    bumpy sphere (``cells`` per cube edge) when there is no path, no such file or no
    trimesh; the third value names the source."""
    if path is not None and not os.path.exists(path):
        print(f"{path} does not exist: using the bumpy sphere")
    elif path is not None:
        try:
            import trimesh
        except ImportError:
            print("trimesh is not installed (pip install kdsl[geometry]): using the bumpy sphere")
        else:
            tm = trimesh.load(path, force="mesh")
            return (np.asarray(tm.vertices, np.float32), np.asarray(tm.faces, np.int32), path)
    pts, faces = bumpy_cube_sphere(cells)
    return pts, faces, "bumpy cube-sphere"


def run(path: str | None = None, num_points: int = 100_000, device: str = "cpu",
        seed: int = 0, cells: int = 129) -> dict:  # fmt: skip
    """Load (or generate, ``cells`` per cube edge) the mesh, project ``num_points``
    random points around it and print a short summary; returns the numbers printed."""
    pts, faces, source = load_mesh(path, cells)
    mesh = wp.Mesh(wp.array(pts, dtype=wp.vec3, device=device),
                   wp.array(faces.reshape(-1), dtype=int, device=device))  # fmt: skip
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    rng = np.random.default_rng(seed)
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * 1.2
    x = (centre + half * rng.uniform(-1, 1, (num_points, 3))).astype(np.float32)
    positions = wp.array(x, dtype=wp.vec3, device=device)
    out_pos = wp.array(x, dtype=wp.vec3, device=device)  # points farther than 2 stay put
    out_face = wp.full(num_points, -1, dtype=int, device=device)
    wp.launch(project, dim=num_points, inputs=[positions, mesh.id, out_pos, out_face],
              device=device)  # warm-up: compiles  # fmt: skip
    wp.synchronize_device(device)
    t = time.perf_counter()
    wp.launch(project, dim=num_points, inputs=[positions, mesh.id, out_pos, out_face],
              device=device)  # fmt: skip
    wp.synchronize_device(device)
    seconds = time.perf_counter() - t
    q, f = out_pos.numpy(), out_face.numpy()
    found = f >= 0
    tri = pts[faces[f[found]]].astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    off_plane = np.abs(np.einsum("ij,ij->i", q[found] - tri[:, 0], normal))
    moved = np.linalg.norm(q - x, axis=1)[found]
    summary = {
        "source": source, "points": num_points, "faces": len(faces), "found": int(found.sum()),
        "mean_distance": float(moved.mean()) if found.any() else 0.0,
        "max_off_plane": float(off_plane.max()) if found.any() else 0.0, "seconds": seconds,
    }  # fmt: skip
    print(f"{source}: {len(faces):,} triangles on {device}")
    print(f"projected {summary['found']:,} of {num_points:,} points in {1e3 * seconds:.1f} ms; "
          f"mean distance {summary['mean_distance']:.4f}, "
          f"largest distance from the face's plane {summary['max_off_plane']:.1e}")  # fmt: skip
    return summary


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("mesh_file", nargs="?", help="an OBJ/PLY/STL file (needs trimesh)")
    p.add_argument("--points", type=int, default=100_000)
    p.add_argument("--device", default="cpu")
    p.add_argument(
        "--cells",
        type=int,
        default=129,
        help="the generated sphere's cells per cube edge (12 * cells**2 triangles)",
    )
    args = p.parse_args(argv)
    run(args.mesh_file, args.points, args.device, cells=args.cells)


if __name__ == "__main__":
    main(sys.argv[1:])
