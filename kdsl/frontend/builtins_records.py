"""``object_record(id, T)``: the record of a runtime object, for library code.

The standard library's geometry queries start from an object's ``uint64`` id (a
``Mesh``'s or ``Bvh``'s ``.id``) and read its record, a struct of the object's
arrays (see ``kdsl.ir.records``). User code that defines its own runtime objects
can do the same.
"""

from __future__ import annotations

from kdsl.errors import KdslTypeError
from kdsl.frontend.builtins_base import BuiltinTable
from kdsl.frontend.values import describe
from kdsl.ir.records import check_record_type
from kdsl.ir.types import U64

TABLE = BuiltinTable(__name__)


@TABLE.define("object_record", (2, 2), "``object_record(id, T)``: the record of struct type "
              "``T`` (a ``@kdsl.struct`` whose first field is a ``uint64`` tag) of the runtime "
              "object with ``uint64`` id ``id`` (its address on the running device). The "
              "geometry queries are built on it; debug builds check the id names a live "
              "object of that record type.", "utility")  # fmt: skip
def _object_record(em, args, node):
    rid, rtype = args
    t = getattr(rtype, "__kdsl_type__", None)
    try:
        check_record_type(t)
    except TypeError as e:
        raise em.error(KdslTypeError, f"object_record(): {e} ({describe(rtype)})", node) from None
    v = em.value(rid, node, want=U64)
    if v.type != U64:
        raise em.error(KdslTypeError, f"object_record() needs a uint64 id, not a {v.type}", node)
    return em.emit_typed("kd.record", [v], t, node)
