"""Object records: a runtime object's arrays and scalars read in kernels by its id.

A record round trip on every host backend (array fields of any ndim and element
type, vectors, bools, nested structs), and the debug check that stops a kernel
reading a null, freed or foreign id (``kd.check_record``).
"""

from __future__ import annotations

import gc

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import KdslRuntimeError, KdslTypeError
from kdsl.runtime.objects import ObjectRecord, owner_of

BACKENDS = ["interp", "cpu"]


@wp.struct
class Inner:
    scale: wp.float32
    flag: wp.bool


@wp.struct
class GridRecord:
    tag: wp.uint64
    values: wp.array2d(dtype=wp.float32)
    points: wp.array(dtype=wp.vec3)
    inner: Inner
    origin: wp.vec3
    count: wp.int32


class Grid:
    """A small user-defined runtime object: a 2-d array and points behind one id."""

    def __init__(self, values: np.ndarray, points: np.ndarray, device: str = "cpu") -> None:
        self.values = wp.array(values, dtype=wp.float32, device=device)
        self.points = wp.array(points, dtype=wp.vec3, device=device)
        self.record = ObjectRecord(self, GridRecord.__kdsl_type__, "grid", device)
        inner = np.zeros((), dtype=[("scale", np.float32), ("flag", np.bool_)])
        inner["scale"], inner["flag"] = 2.5, True
        self.record.write(
            {"values": self.values, "points": self.points, "inner": inner,
             "origin": (1.0, 2.0, 3.0), "count": len(points)}
        )  # fmt: skip

    @property
    def id(self) -> int:
        return self.record.id


@wp.kernel
def read_grid(grid: wp.uint64, out: wp.array(dtype=wp.float32)):
    i = wp.tid()
    g = wp.object_record(grid, GridRecord)
    row = i % g.values.shape[0]
    col = i % g.values.shape[1]
    p = g.points[i % g.count]
    s = g.inner.scale
    if not g.inner.flag:
        s = 0.0
    out[i] = g.values[row, col] * s + wp.dot(p, g.origin)


@pytest.mark.parametrize("backend", BACKENDS)
def test_record_round_trip(backend):
    rng = np.random.default_rng(1)
    values = rng.random((3, 5)).astype(np.float32)
    points = rng.random((4, 3)).astype(np.float32)
    grid = Grid(values[:, ::-1].copy(), points)
    n = 12
    out = wp.zeros(n, dtype=wp.float32)
    wp.launch(read_grid, dim=n, inputs=[grid.id, out], backend=backend)
    v = values[:, ::-1]
    want = [v[i % 3, i % 5] * 2.5 + points[i % 4] @ np.array([1.0, 2.0, 3.0]) for i in range(n)]
    np.testing.assert_allclose(out.numpy(), want, rtol=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_record_of_a_strided_view(backend):
    # A view's strides reach the kernel in the record (bytes) and index correctly.
    base = np.arange(40, dtype=np.float32).reshape(4, 10)
    grid = Grid(np.zeros((1, 1), np.float32), np.zeros((1, 3), np.float32))
    view = wp.array(base)[:, ::3]
    grid.values = view
    grid.record.write(
        {"values": view, "points": grid.points,
         "inner": np.array((1.0, True), dtype=[("scale", np.float32), ("flag", np.bool_)]),
         "origin": (0.0, 0.0, 0.0), "count": 1}
    )  # fmt: skip
    out = wp.zeros(8, dtype=wp.float32)
    wp.launch(read_grid, dim=8, inputs=[grid.id, out], backend=backend)
    vv = base[:, ::3]
    np.testing.assert_array_equal(out.numpy(), [vv[i % 4, i % 4] for i in range(8)])


@wp.kernel(debug=True)
def read_count(grid: wp.uint64, out: wp.array(dtype=wp.int32)):
    out[0] = wp.object_record(grid, GridRecord).count


@pytest.mark.parametrize("backend", BACKENDS)
def test_debug_check_catches_null_freed_and_foreign_ids(backend):
    out = wp.zeros(1, dtype=wp.int32)
    with pytest.raises(KdslRuntimeError, match=r"object id 0 \(a null id\) as a GridRecord"):
        wp.launch(read_count, dim=1, inputs=[0, out], backend=backend)
    grid = Grid(np.zeros((2, 2), np.float32), np.zeros((3, 3), np.float32))
    wp.launch(read_count, dim=1, inputs=[grid.id, out], backend=backend)
    assert out.numpy()[0] == 3
    stale = grid.id
    assert owner_of(stale)[0] is grid
    del grid
    gc.collect()
    assert owner_of(stale) is None
    with pytest.raises(KdslRuntimeError, match="no live object of that kind has this id"):
        wp.launch(read_count, dim=1, inputs=[stale, out], backend=backend)
    lo = wp.array(np.zeros((2, 3), np.float32), dtype=wp.vec3)
    bvh = wp.Bvh(lo, lo)
    with pytest.raises(KdslRuntimeError, match="as a GridRecord"):
        wp.launch(read_count, dim=1, inputs=[bvh.id, out], backend=backend)


def test_object_record_type_errors():
    @wp.kernel
    def not_a_record(grid: wp.uint64, out: wp.array(dtype=float)):
        out[0] = wp.object_record(grid, Inner).scale

    with pytest.raises(KdslTypeError, match="first field is a uint64 tag"):
        wp.launch(not_a_record, dim=1, inputs=[0, wp.zeros(1)])

    @wp.kernel
    def float_id(x: float, out: wp.array(dtype=wp.int32)):
        out[0] = wp.object_record(x, GridRecord).count

    with pytest.raises(KdslTypeError, match="needs a uint64 id"):
        wp.launch(float_id, dim=1, inputs=[1.0, wp.zeros(1, dtype=wp.int32)])


def test_freed_slots_are_recycled_oldest_first():
    a = Grid(np.zeros((1, 1), np.float32), np.zeros((1, 3), np.float32))
    b = Grid(np.zeros((1, 1), np.float32), np.zeros((1, 3), np.float32))
    first, second = a.id, b.id
    a.record.free()
    b.record.free()
    # Older freed slots (other tests') may come first; ``first`` must come before ``second``.
    keep = []
    while True:
        keep.append(Grid(np.zeros((1, 1), np.float32), np.zeros((1, 3), np.float32)))
        if keep[-1].id in (first, second):
            assert keep[-1].id == first
            break


def test_an_id_of_another_devices_object_is_refused_at_launch(monkeypatch):
    from kdsl.runtime import objects

    grid = Grid(np.zeros((1, 1), np.float32), np.zeros((1, 3), np.float32))
    owner, kind, _ = objects.owner_of(grid.id)
    assert owner is grid
    # As if the object lived on a GPU: the launch on cpu names both devices.
    monkeypatch.setitem(objects._owners, grid.id, (objects._owners[grid.id][0], kind, "cuda:0"))
    with pytest.raises(wp.KdslLaunchError, match="is the id of a grid on device 'cuda:0'"):
        wp.launch(read_count, dim=1, inputs=[grid.id, wp.zeros(1, dtype=wp.int32)])


def numpy_record(t, fields: dict) -> bytes:
    """A record's bytes by NumPy field assignment (``pack_record``'s reference)."""
    from kdsl.ir.records import record_dtype, record_tag

    rec = np.zeros((), dtype=record_dtype(t))
    rec[t.fields[0][0]] = record_tag(t.name)
    for name, _ in t.fields[1:]:
        v = fields[name]
        rec[name] = [v.ptr or 0, *v.shape, *v.strides] if isinstance(v, wp.array) else np.asarray(v)
    return rec.tobytes()


@pytest.mark.parametrize("count", [7, np.int32(7), True, 7.9, np.float64(-3.0), 2**31 + 5])
@pytest.mark.parametrize("scale", [2.5, np.float32(0.1), 3, np.float64(1e40), 1e40])
def test_packed_records_match_numpy_field_by_field(count, scale):
    """``pack_record`` packs descriptors and exact Python scalars by ``struct``, the rest
    by NumPy: the same bytes as NumPy's assignment of every field, casts included."""
    from kdsl.stdlib.hash_grid import HashGridRecord

    values = wp.zeros((3, 4), dtype=wp.float32)
    points = wp.zeros(5, dtype=wp.vec3)[1::2]  # a strided view
    inner = np.zeros((), dtype=[("scale", np.float32), ("flag", np.bool_)])
    fields = {"values": values, "points": points, "inner": inner, "origin": (1.0, 2.0, scale),
              "count": count}  # fmt: skip
    with np.errstate(over="ignore"):
        same_as_numpy(GridRecord.__kdsl_type__, fields)
        ids = wp.zeros(6, dtype=wp.int32)
        grid = {"point_ids": ids, "cell_starts": ids[::3], "cell_ends": ids[:0],
                "dim_x": count, "dim_y": 2, "dim_z": 3, "num_points": count,
                "cell_width_inv": scale}  # fmt: skip
        same_as_numpy(HashGridRecord.__kdsl_type__, grid)


def same_as_numpy(t, fields: dict) -> None:
    """``pack_record`` gives NumPy's bytes, or raises NumPy's error."""
    from kdsl.runtime.objects import pack_record

    try:
        want = numpy_record(t, fields)
    except (OverflowError, ValueError, TypeError) as e:
        with pytest.raises(type(e)):
            pack_record(t, fields)
        return
    assert pack_record(t, fields) == want
