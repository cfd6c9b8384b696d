"""Iso-surface extraction contexts with Warp's API: ``kdsl.geometry.IsoSurfaceBase``,
``IsoSurfaceMarchingCubes`` (Warp 1.19's ``warp.geometry`` names) and
``kdsl.MarchingCubes`` (Warp's older constructor, ``max_verts``/``max_tris``/``device``).

A context holds the grid's node counts and the bounds its nodes map to; ``surface``
extracts a field's iso-surface into ``verts`` and ``indices``, new arrays on the field's
device each call (as Warp: a ``kdsl.Mesh`` built on the previous ones keeps them).
The extraction itself is ``kdsl.geometry.marching_cubes``.
"""

from __future__ import annotations

import warnings
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from kdsl.geometry import marching_cubes_tables as tables
from kdsl.geometry.marching_cubes import (
    MarchingCubesError,
    MarchingCubesTypeError,
    Scratch,
    check_dims,
    check_field,
    extract_surface,
)
from kdsl.runtime.array import array
from kdsl.runtime.device import get_device

#: Bounds as Warp takes them: a vec3, a 3-tuple, or None for the default.
Bounds = Any


def _int_at_least(name: str, value: Any, least: int, what: str) -> int:
    """``value`` as an int (NumPy ints too, bools not) of at least ``least``."""
    n = None if isinstance(value, bool) else getattr(value, "__index__", None)
    if n is None:
        raise MarchingCubesTypeError(f"{name} must be an int, not {value!r}")
    if n() < least:
        raise MarchingCubesError(f"{name} must be {what}, not {value!r}")
    return n()


def check_node_counts(nx: Any, ny: Any, nz: Any) -> tuple[int, int, int]:
    """``(nx, ny, nz)`` as ints of at least 2 whose grid fits int32 edge indices."""
    dims = tuple(_int_at_least(name, v, 2, "at least 2 nodes (one cell)")
                 for name, v in (("nx", nx), ("ny", ny), ("nz", nz)))  # fmt: skip
    check_dims(*dims)
    return dims


def as_bound(name: str, value: Bounds) -> np.ndarray:
    """``value`` (a vec3 or 3 numbers) as a float32 array of 3 finite numbers, else a
    marching cubes error naming ``name``."""
    try:
        v = np.asarray(value, dtype=np.float32).reshape(3)
    except (TypeError, ValueError):
        raise MarchingCubesTypeError(f"{name} must be a vec3 or 3 numbers, not {value!r}") from None
    if not np.isfinite(v).all():
        raise MarchingCubesError(f"{name} must be finite, not {tuple(v.tolist())}")
    return v


def resolve_domain_bounds(
    shape: tuple[int, int, int], lower: Bounds, upper: Bounds
) -> tuple[np.ndarray, np.ndarray]:
    """``(lower, delta)`` in float32 (Warp's arithmetic): node ``(i, j, k)`` maps to
    ``lower + (i, j, k) * delta``. ``lower`` defaults to the origin and ``upper`` (where
    the last node maps) to ``shape - 1``, so positions are grid indices by default."""
    lo = np.zeros(3, np.float32) if lower is None else as_bound("lower", lower)
    hi = np.array(shape, np.float32) - 1 if upper is None else as_bound("upper", upper)
    cells = np.array(shape, np.float32) - 1
    return lo, (hi - lo) / cells


class IsoSurfaceBase(ABC):
    """An iso-surface extractor for dense float32 fields of ``nx * ny * nz`` nodes,
    as ``warp.geometry.IsoSurfaceBase``: ``surface(field, threshold)`` fills ``verts``
    (vec3) and ``indices`` (int32, one face after another); ``extract`` is the
    stateless form. ``lower``/``upper`` are where nodes ``(0, 0, 0)`` and
    ``(nx - 1, ny - 1, nz - 1)`` map (default: node indices)."""

    def __init__(
        self, nx: int, ny: int, nz: int, *, lower: Bounds = None, upper: Bounds = None
    ) -> None:
        self.nx, self.ny, self.nz = check_node_counts(nx, ny, nz)
        self.lower = lower
        self.upper = upper
        #: The vertex positions of the last ``surface`` (vec3), or None before one.
        self.verts: array | None = None
        #: The face vertex indices of the last ``surface`` (int32), or None before one.
        self.indices: array | None = None

    def resize(self, nx: int, ny: int, nz: int) -> None:
        """Take fields of ``nx * ny * nz`` nodes from the next ``surface`` on."""
        self.nx, self.ny, self.nz = check_node_counts(nx, ny, nz)

    def _check_field_shape(self, field: array) -> None:
        check_field(field)
        if tuple(field.shape) != (self.nx, self.ny, self.nz):
            raise MarchingCubesError(f"field shape {tuple(field.shape)} does not match the "
                                     f"context's grid {(self.nx, self.ny, self.nz)}")  # fmt: skip

    @abstractmethod
    def surface(self, field: array, threshold: float) -> None:
        """Extract the ``threshold`` iso-surface of ``field`` (shape ``(nx, ny, nz)``)
        into ``verts`` and ``indices``."""

    @classmethod
    @abstractmethod
    def extract(
        cls, field: array, threshold: float = 0.0, *, lower: Bounds = None, upper: Bounds = None
    ) -> tuple[array, array]:
        """``(verts, indices)`` of the ``threshold`` iso-surface of ``field``."""


def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"IsoSurfaceMarchingCubes.{old} is deprecated (as in Warp 1.19): use "
                  f"{new} instead", DeprecationWarning, stacklevel=3)  # fmt: skip


_UNSET = object()


def _bound_alias(old: str, new: str, warn: bool) -> property:
    """A property ``old`` that reads and writes attribute ``new`` (warning that ``old``
    is deprecated when ``warn``)."""

    def get(self: Any) -> Bounds:
        if warn:
            _deprecated(old, new)
        return getattr(self, new)

    def put(self: Any, value: Bounds) -> None:
        if warn:
            _deprecated(old, new)
        setattr(self, new, value)

    return property(get, put, doc=f"``{new}``" + (" (deprecated)" if warn else ""))


class IsoSurfaceMarchingCubes(IsoSurfaceBase):
    """Marching cubes, as ``warp.geometry.IsoSurfaceMarchingCubes``: one vertex per grid
    edge the surface crosses, shared by the triangles around it (a closed surface is
    watertight), each cell's triangles from Bourke's table, in Warp's order and winding.
    A node is inside when its value is at or above ``threshold`` (a NaN never is).

    ``domain_bounds_lower_corner``/``_upper_corner`` are Warp's deprecated spellings
    of ``lower``/``upper``."""

    CUBE_CORNER_OFFSETS = tables.CUBE_CORNER_OFFSETS
    EDGE_TO_CORNERS = tables.EDGE_TO_CORNERS
    CASE_TO_TRI_RANGE = tables.CASE_TO_TRI_RANGE
    TRI_LOCAL_INDICES = tables.TRI_LOCAL_INDICES

    def __init__(
        self, nx: int, ny: int, nz: int, lower: Bounds = None, upper: Bounds = None, *,
        domain_bounds_lower_corner: Bounds = _UNSET, domain_bounds_upper_corner: Bounds = _UNSET,
    ) -> None:  # fmt: skip
        lower = _merge_bound("lower", lower, "domain_bounds_lower_corner",
                             domain_bounds_lower_corner)  # fmt: skip
        upper = _merge_bound("upper", upper, "domain_bounds_upper_corner",
                             domain_bounds_upper_corner)  # fmt: skip
        super().__init__(nx, ny, nz, lower=lower, upper=upper)
        self._scratch: Scratch | None = None

    domain_bounds_lower_corner = _bound_alias("domain_bounds_lower_corner", "lower", warn=True)
    domain_bounds_upper_corner = _bound_alias("domain_bounds_upper_corner", "upper", warn=True)

    def surface(self, field: array, threshold: float) -> None:
        """Extract the ``threshold`` iso-surface of ``field`` (shape ``(nx, ny, nz)``)
        into ``verts`` and ``indices``; the per-node work buffers are kept for the
        next call."""
        self._check_field_shape(field)
        lower, delta = resolve_domain_bounds(field.shape, self.lower, self.upper)
        if self._scratch is None or not self._scratch.fits(field.size, field.device):
            self._scratch = Scratch(field.size, field.device)
        self.verts, self.indices = extract_surface(field, threshold, lower, delta,
                                                   scratch=self._scratch)  # fmt: skip

    @classmethod
    def extract(
        cls, field: array, threshold: float = 0.0, *, lower: Bounds = None, upper: Bounds = None
    ) -> tuple[array, array]:
        """``(verts, indices)`` of the ``threshold`` iso-surface of ``field`` (a 3-d
        float32 array, at least 2 nodes per axis), on the field's device."""
        shape = check_field(field)
        lo, delta = resolve_domain_bounds(shape, lower, upper)
        return extract_surface(field, threshold, lo, delta)

    @staticmethod
    def extract_surface_marching_cubes(
        field: array, threshold: float = 0.0, domain_bounds_lower_corner: Bounds = None,
        domain_bounds_upper_corner: Bounds = None,
    ) -> tuple[array, array]:  # fmt: skip
        """Deprecated (as in Warp 1.19): ``extract``."""
        _deprecated("extract_surface_marching_cubes()", "extract()")
        return IsoSurfaceMarchingCubes.extract(
            field, threshold, lower=domain_bounds_lower_corner, upper=domain_bounds_upper_corner
        )


def _merge_bound(name: str, value: Bounds, old: str, old_value: Bounds) -> Bounds:
    if old_value is _UNSET:
        return value
    if value is not None and old_value is not None:
        raise MarchingCubesTypeError(f"give either {name} or {old}, not both")
    _deprecated(f"__init__ argument {old}", name)
    return value if old_value is None else old_value


class MarchingCubes(IsoSurfaceMarchingCubes):
    """Marching cubes with Warp's ``wp.MarchingCubes`` constructor: ``(nx, ny, nz,
    max_verts=0, max_tris=0, device=None, domain_bounds_lower_corner=None,
    domain_bounds_upper_corner=None)``; ``lower=``/``upper=`` are accepted too.

    ``surface(field, threshold)`` fills ``verts`` and ``indices`` as
    ``IsoSurfaceMarchingCubes`` does. As in Warp (since 1.7), ``max_verts`` and
    ``max_tris`` bound nothing: the outputs are sized by a counting pass, however many
    vertices and triangles the surface has. Where Warp only records ``device``, kdsl
    checks it: a context made for a device refuses a field on another one; with
    ``device=None`` the field's device is used."""

    def __init__(
        self, nx: int, ny: int, nz: int, max_verts: int = 0, max_tris: int = 0,
        device: Any = None, domain_bounds_lower_corner: Bounds = None,
        domain_bounds_upper_corner: Bounds = None, *, lower: Bounds = None, upper: Bounds = None,
    ) -> None:  # fmt: skip
        for name, value, old in (("lower", lower, domain_bounds_lower_corner),
                                 ("upper", upper, domain_bounds_upper_corner)):  # fmt: skip
            if value is not None and old is not None:
                raise MarchingCubesTypeError(f"give either {name} or domain_bounds_"
                                             f"{name}_corner, not both")  # fmt: skip
        super().__init__(
            nx, ny, nz, lower if lower is not None else domain_bounds_lower_corner,
            upper if upper is not None else domain_bounds_upper_corner,
        )  # fmt: skip
        self.max_verts = _int_at_least("max_verts", max_verts, 0, "a count >= 0")
        self.max_tris = _int_at_least("max_tris", max_tris, 0, "a count >= 0")
        #: The device given (the default device for None), as Warp's attribute.
        self.device = get_device(device)
        self._device_given = device is not None
        #: 0: Warp's unused native handle, kept for code that reads it.
        self.id = 0

    # The older API's own attributes: plain aliases of lower/upper, no warning.
    domain_bounds_lower_corner = _bound_alias("domain_bounds_lower_corner", "lower", warn=False)
    domain_bounds_upper_corner = _bound_alias("domain_bounds_upper_corner", "upper", warn=False)

    def resize(self, nx: int, ny: int, nz: int, max_verts: int = 0, max_tris: int = 0) -> None:
        """Take fields of ``nx * ny * nz`` nodes from the next ``surface`` on
        (``max_verts``/``max_tris`` are recorded and bound nothing, as in Warp)."""
        super().resize(nx, ny, nz)
        self.max_verts = _int_at_least("max_verts", max_verts, 0, "a count >= 0")
        self.max_tris = _int_at_least("max_tris", max_tris, 0, "a count >= 0")

    def surface(self, field: array, threshold: float) -> None:
        """Extract the ``threshold`` iso-surface of ``field`` (shape ``(nx, ny, nz)``,
        on the context's device when one was given) into ``verts`` and ``indices``."""
        if self._device_given and isinstance(field, array) and field.device != self.device:
            raise MarchingCubesTypeError(f"MarchingCubes.surface field is on {field.device}, "
                                         f"the context on {self.device}")  # fmt: skip
        super().surface(field, threshold)


__all__ = ["IsoSurfaceBase", "IsoSurfaceMarchingCubes", "MarchingCubes"]
