"""Geometry objects on the shared runtime: ``Bvh`` (and, built on it, ``Mesh``) and
``HashGrid``.

Their queries are kernel code in the standard library (``kdsl.stdlib.bvh``); this
package builds and updates the objects' arrays and records.
"""

from kdsl.geometry.bvh import Bvh
from kdsl.geometry.hash_grid import HashGrid
from kdsl.geometry.mesh import Mesh

__all__ = ["Bvh", "HashGrid", "Mesh"]
