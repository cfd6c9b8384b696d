"""Geometry objects on the shared runtime: ``Bvh`` (and, built on it, ``Mesh``) and
``HashGrid``; sparse NanoVDB volumes (``Volume``, format code in
``kdsl.geometry.nanovdb``); iso-surface extraction (``MarchingCubes``, and Warp 1.19's
``kdsl.geometry.IsoSurfaceMarchingCubes``).

Their queries are kernel code in the standard library (``kdsl.stdlib.bvh``); this
package builds and updates the objects' arrays and records.
"""

from kdsl.geometry.bvh import Bvh
from kdsl.geometry.hash_grid import HashGrid
from kdsl.geometry.iso_surface import IsoSurfaceBase, IsoSurfaceMarchingCubes, MarchingCubes
from kdsl.geometry.mesh import Mesh
from kdsl.geometry.sparse_marching_cubes import (
    lipschitz_octree,
    sparse_marching_cubes,
    sparse_marching_cubes_from_cells,
)
from kdsl.geometry.surface_nets import IsoSurfaceNets
from kdsl.geometry.volume import Volume

# IsoSurfaceBase, IsoSurfaceMarchingCubes, IsoSurfaceNets and sparse marching cubes live
# in kdsl.geometry only, as in Warp.
__all__ = ["Bvh", "HashGrid", "MarchingCubes", "Mesh", "Volume"]
