"""examples/mesh_project.py, run small: the generated sphere, a mesh file through
trimesh (when installed), the fallback for a missing file; the projected points lie on
their faces at the brute-force closest distance."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.geometry.mesh_reference import closest_distances

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "mesh_project.py"


@pytest.fixture(scope="module")
def example():
    key = "kdsl_example_mesh_project"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, EXAMPLE)
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        spec.loader.exec_module(module)
    return sys.modules[key]


def test_bumpy_cube_sphere_is_closed_and_outward(example):
    pts, faces = example.bumpy_cube_sphere(4)
    assert faces.shape == (12 * 16, 3) and faces.dtype == np.int32
    assert len(pts) == 6 * 16 + 2  # 6 n^2 + 2 vertices: the cube's seams merged
    # every edge is shared by exactly two faces, once in each direction
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    assert len({tuple(e) for e in edges.tolist()}) == len(edges)
    assert {tuple(e) for e in edges[:, ::-1].tolist()} == {tuple(e) for e in edges.tolist()}
    tri = pts[faces].astype(np.float64)
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert 3.5 < volume < 4.5  # outward: positive, about the unit ball's 4.19


def test_generated_sphere(example, capsys):
    out = example.run(None, num_points=300, cells=6)
    printed = capsys.readouterr().out
    assert "bumpy cube-sphere: 432 triangles on cpu" in printed
    assert "projected 300 of 300 points" in printed
    assert out["found"] == 300 and out["max_off_plane"] < 1e-5
    pts, faces = example.bumpy_cube_sphere(6)
    rng = np.random.default_rng(0)  # the example's points (same seed, same box)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    x = ((lo + hi) / 2 + (hi - lo) / 2 * 1.2 * rng.uniform(-1, 1, (300, 3))).astype(np.float32)
    ref = closest_distances(pts, faces, x)
    assert out["mean_distance"] == pytest.approx(ref.mean(), rel=1e-4)


@pytest.mark.parametrize("suffix", ["obj", "ply", "stl"])
def test_mesh_file_through_trimesh(example, tmp_path, capsys, suffix):
    trimesh = pytest.importorskip("trimesh")
    path = tmp_path / f"box.{suffix}"
    trimesh.creation.box(extents=(1.0, 2.0, 0.5)).export(path)
    out = example.run(str(path), num_points=200)
    printed = capsys.readouterr().out
    assert f"{path}: 12 triangles on cpu" in printed
    assert out["faces"] == 12 and out["found"] == 200 and out["max_off_plane"] < 1e-5


def test_missing_file_falls_back_to_the_sphere(example, tmp_path, capsys):
    out = example.run(str(tmp_path / "nothing.stl"), num_points=50, cells=3)
    printed = capsys.readouterr().out
    assert "does not exist: using the bumpy sphere" in printed
    assert out["source"] == "bumpy cube-sphere" and out["faces"] == 12 * 9


def test_without_trimesh_falls_back_to_the_sphere(example, tmp_path, capsys, monkeypatch):
    path = tmp_path / "mesh.ply"
    path.write_text("ply\n")
    monkeypatch.setitem(sys.modules, "trimesh", None)  # import trimesh raises ImportError
    out = example.run(str(path), num_points=50, cells=3)
    assert "trimesh is not installed" in capsys.readouterr().out
    assert out["source"] == "bumpy cube-sphere"
