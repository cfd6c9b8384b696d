"""The debug dialect: run-time checks that debug mode inserts (``bounds-check``, ``fp-check``).

``kd.check_bounds %arr, %i... {arg, site}`` fails when an index is outside the
array's shape; it is placed right before the access it guards. ``kd.check_record %id
{arg, site}`` fails when ``id`` is not the id of a live object whose record has type
``arg`` (see ``kdsl.ir.records``); it is placed right before the ``kd.record``. ``kd.check_finite
%value {arg, site}`` fails when a float value (any lane of a vector or matrix)
is NaN or infinite; it is placed before the store that writes the value.

``site`` numbers the checks of a module; ``debug_sites`` maps each number to the
kernel or function holding the check, the array's name and the source location,
so a backend that only reports "site 3 failed" can name the source line. The
ops carry the WRITES trait (a failed check stops a thread, an effect) so no pass
removes, merges or reorders them.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from kdsl.errors import KdslRuntimeError
from kdsl.ir.builder import create_op
from kdsl.ir.catalog import CATALOG, CHECK, WRITES, InterpRule, OpDef, TypeRule
from kdsl.ir.core import Loc, Module, Operation, Value
from kdsl.ir.ops_mem import check_access, element_index
from kdsl.ir.records import record_tag
from kdsl.ir.types import U64, ScalarType, Type, elem_type


def _bounds_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    check_access(ts[0], ts[1:], "kd.check_bounds checks an array", partial=True)
    return []


def _verify_site(op: Operation) -> None:
    site = op.attrs["site"]
    if not isinstance(site, int) or isinstance(site, bool) or site < 0:
        raise TypeError(f"{op.name} needs a non-negative integer site, not {site!r}")
    if not isinstance(op.attrs.get("arg", ""), str):
        raise TypeError(f"{op.name}: arg must be a string")


def _define_check(name: str, doc: str, type_rule: TypeRule, interp: InterpRule, example: str):
    """A check op: its only effect stops a failing thread; ``arg`` and ``site`` attributes."""
    return CATALOG.define(
        name, doc, traits=frozenset({WRITES, CHECK}), type_rule=type_rule, verifier=_verify_site,
        interp=interp, required_attrs=("arg", "site"), example=example, group="debug",
    )  # fmt: skip


def _bounds_interp(ctx, op, a, *idx):
    element_index(ctx, op, a, 0, idx)  # raises the same error a load would


CHECK_BOUNDS = _define_check(
    "kd.check_bounds",
    "Debug mode: stop with an error when an index is outside the array's shape (all "
    "of its dims, or the leading ones a ``kd.array_view`` takes). "
    "``arg`` names the array (for messages); ``site`` numbers the check in its module.",
    _bounds_rule, _bounds_interp, 'kd.check_bounds %0, %1 {arg = "y", site = 0}',
)  # fmt: skip


def _finite_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    (v,) = ts
    try:
        et = elem_type(v)
    except (TypeError, AttributeError):
        et = None
    if not (isinstance(et, ScalarType) and et.is_float):
        raise TypeError(f"kd.check_finite checks float values, not {v}")
    return []


def nonfinite_kind(value: Any) -> str | None:
    """``"NaN"`` or ``"Inf"`` when any component of ``value`` is one, else None."""
    arr = np.asarray(value)
    if np.isnan(arr).any():
        return "NaN"
    if np.isinf(arr).any():
        return "Inf"
    return None


def _finite_interp(ctx, op, v):
    kind = nonfinite_kind(v)
    if kind is not None:
        kernel = getattr(ctx, "kernel_name", "?")
        msg = fp_message(kernel, kind, op.attrs.get("arg", ""), op.loc)
        raise KdslRuntimeError(msg, op.loc, kernel)


CHECK_FINITE = _define_check(
    "kd.check_finite",
    "Debug mode (``verify_fp``): stop with an error when a float value (any lane) is NaN "
    "or infinite. ``arg`` names the array the value is stored into; ``site`` numbers "
    "the check in its module.",
    _finite_rule, _finite_interp, 'kd.check_finite %3 {arg = "y", site = 1}',
)  # fmt: skip


def _record_check_rule(ts: Sequence[Type], attrs: dict[str, Any]) -> list[Type]:
    if list(ts) != [U64]:
        raise TypeError(f"kd.check_record checks one uint64 id, not {list(map(str, ts))}")
    return []


#: What a record's address can be: at least ``RECORD_ID_MIN`` (no mapping lies below
#: Linux's first 64 KiB), below ``RECORD_ID_END`` (48-bit user space, host and CUDA)
#: and a multiple of ``RECORD_ALIGN``. ``kd.check_record`` reads a tag only at such an
#: address, so a small, odd or random id (never an object's) fails without a read.
RECORD_ID_MIN = 1 << 16
RECORD_ID_END = 1 << 47
RECORD_ALIGN = 16


def plausible_record_id(address: int) -> bool:
    """Whether ``address`` may be a record's (see ``RECORD_ID_MIN``): safe to read."""
    return RECORD_ID_MIN <= address < RECORD_ID_END and address % RECORD_ALIGN == 0


#: Whether a host address lies in the memory that holds host records (set by the
#: runtime, ``kdsl.runtime.objects``, with ``set_host_record_memory``); the interpreter
#: reads only such addresses, so no id can crash it. None: any plausible id is read.
_host_record_memory: Callable[[int], bool] | None = None


def set_host_record_memory(test: Callable[[int], bool]) -> None:
    """Give the interpreter's ``kd.check_record`` the test of host record memory."""
    global _host_record_memory
    _host_record_memory = test


def record_alive(address: int, record: str) -> bool:
    """Whether ``address`` holds a live record of the struct type named ``record``."""
    if not plausible_record_id(address):
        return False
    if _host_record_memory is not None and not _host_record_memory(address):
        return False
    return int.from_bytes(ctypes.string_at(address, 8), "little") == record_tag(record)


def _record_check_interp(ctx, op, rid):
    if not record_alive(int(rid), op.attrs["arg"]):
        kernel = getattr(ctx, "kernel_name", "?")
        raise KdslRuntimeError(record_message(kernel, op.attrs["arg"], int(rid)), op.loc, kernel)


CHECK_RECORD = _define_check(
    "kd.check_record",
    "Debug mode: stop with an error when ``id`` is not the id of a live runtime object "
    "whose record is the struct named ``arg`` (0, freed, or never an object's id): the "
    "id must be a plausible address (``plausible_record_id``: otherwise nothing is read) "
    "and the record's first word that struct's tag (``kdsl.ir.records.record_tag``). "
    "``site`` numbers the check in its module.",
    _record_check_rule, _record_check_interp, 'kd.check_record %0 {arg = "BvhRecord", site = 2}',
)  # fmt: skip


#: The ops that hold a ``site`` attribute.
CHECK_OPS = (CHECK_BOUNDS, CHECK_FINITE, CHECK_RECORD)


@dataclass(frozen=True)
class Site:
    """Where one check is: its op, the function holding it, the array's name, the source."""

    op: str
    func: str
    arg: str
    loc: Loc
    #: Number of indices of a bounds check (0 for a finite check).
    ndim: int = 0


def debug_sites(module: Module) -> dict[int, Site]:
    """Every check of ``module`` by site number."""
    out: dict[int, Site] = {}
    for func in module.funcs:
        for op in func.walk():
            if op.opdef in CHECK_OPS:
                ndim = len(op.operands) - 1 if op.opdef is CHECK_BOUNDS else 0
                out[op.attrs["site"]] = Site(
                    op.name, func.attrs["sym_name"], op.attrs.get("arg", ""), op.loc, ndim
                )
    return out


def next_site(module: Module) -> int:
    """The first site number no check of ``module`` uses."""
    return max(debug_sites(module), default=-1) + 1


#: Where a pass wants a check of an access: the check's operands and the op it goes
#: right before (the access, or an earlier check of it).
CheckPlan = tuple[list[Value], Operation]


def insert_checks(
    module: Module,
    check: OpDef,
    plan: Callable[[Operation], CheckPlan | None],
    arg_of: Callable[[Operation], str] | None = None,
) -> bool:
    """Insert a ``check`` op for every access that ``plan`` asks one for; True if any.

    Each check takes the access's location, the name of its array (``arg``, or what
    ``arg_of`` gives for the op) and the next free ``site`` number. Checks inserted
    here are not visited themselves.
    """
    first = site = next_site(module)
    for func in module.funcs:
        for op in list(func.walk()):
            planned = plan(op)
            if planned is None:
                continue
            operands, anchor = planned
            at = op.opdef.array_operand  # None for a kd.array_view: its array comes first
            arg = op.operands[at if at is not None else 0].name_hint or "array"
            if arg_of is not None:
                arg = arg_of(op)
            new = create_op(check.name, operands, [], {"arg": arg, "site": site}, loc=op.loc)
            anchor.parent.insert_before(anchor, new)
            site += 1
    return site > first


def bounds_message(kernel: str, arg: str, index: Sequence[int], shape: Sequence[int]) -> str:
    """The message of a failed bounds check (the same on every backend)."""
    return (
        f"index {list(index)} is out of bounds for array '{arg or 'array'}' of shape "
        f"{tuple(shape)} in kernel '{kernel}'"
    )


def record_message(kernel: str, record: str, address: int) -> str:
    """The message of a failed ``kd.check_record``."""
    what = "0 (a null id)" if address == 0 else f"{address:#x}"
    return (
        f"kernel '{kernel}' read object id {what} as a {record}, but no live object of that "
        "kind has this id (never built, freed, or an id of another kind or device)"
    )


def fp_message(kernel: str, kind: str, arg: str, loc: Loc | None = None) -> str:
    """The message of a failed ``kd.check_finite``."""
    where = f" at line {loc.line}" if loc is not None and loc.line > 0 else ""
    into = f" (a value stored into array '{arg}')" if arg else ""
    return f"kernel '{kernel}' produced {kind}{where}{into}"
