"""Lowerings of the debug checks (``kd.check_bounds``, ``kd.check_finite``) on CUDA.

Debug builds take one more kernel parameter, ``long long *kd_err``: the error record
of ``kdsl.backends.checks_common`` in device memory, zeroed before the launch and
read back after it. A failing check claims its slot with ``atomicCAS`` from 0, so
the first failure (in time) wins and only it writes the details. A failed bounds
check then returns from the kernel (or from a called function, whose caller tests
the record after the call and returns too), so the bad access never runs and the
device stays usable. A failed finite check only records.
"""

from __future__ import annotations

from kdsl.backends import checks_common as R
from kdsl.backends.cuda import ctypes_ as CT
from kdsl.backends.cuda.arith import is_f16
from kdsl.backends.cuda.emitter import FuncEmitter
from kdsl.errors import KdslCapabilityError
from kdsl.ir import types as T
from kdsl.ir.core import Operation
from kdsl.ir.lowering import LOWERINGS
from kdsl.ir.ops_debug import RECORD_ALIGN, RECORD_ID_END, RECORD_ID_MIN
from kdsl.ir.records import record_tag

CUDA = LOWERINGS.for_backend("cuda")


def _require_debug(em: FuncEmitter, op: Operation) -> None:
    if not em.src.debug:
        raise KdslCapabilityError(
            f"{op.name} needs a debug build (compile with debug=True or verify_fp=True)", op.loc
        )


def _tid(em: FuncEmitter) -> str:
    return "(long long)kd_i" if em.is_kernel else "-1ll"


def abort(em: FuncEmitter) -> str:
    """The statement that ends the current thread (or function) after a failed check."""
    if em.is_kernel or em.ret_type == "void":
        return "return;"
    return f"return {em.ret_type}{{}};"


def stop_if_failed(em: FuncEmitter) -> None:
    """After a call in a debug build: end this thread too if a bounds check failed."""
    if em.src.debug:
        em.line(f"if (*(volatile long long *)kd_err != 0) {abort(em)}")


def _claim(word: int, site: int) -> str:
    return f"atomicCAS((unsigned long long *)(kd_err + {word}), 0ull, {site + 1}ull) == 0ull"


def _check_bounds(em: FuncEmitter, op: Operation) -> None:
    _require_debug(em, op)
    arr = em.get(op.operands[0])
    idx = [f"(long long){em.get(v)}" for v in op.operands[1:]]
    inside = " && ".join(
        f"(unsigned long long){i} < (unsigned long long){arr}.shape[{k}]" for k, i in enumerate(idx)
    )
    em.open(f"if (!({inside})) {{")
    em.open(f"if ({_claim(R.BOUNDS, op.attrs['site'])}) {{")
    em.line(f"kd_err[{R.BOUNDS_TID}] = {_tid(em)};")
    for k, i in enumerate(idx[: R.MAX_NDIM]):
        em.line(
            f"kd_err[{R.BOUNDS_IDX + k}] = {i}; kd_err[{R.BOUNDS_SHAPE + k}] = {arr}.shape[{k}];"
        )
    em.close()
    em.line(abort(em))
    em.close()


def _check_finite(em: FuncEmitter, op: Operation) -> None:
    _require_debug(em, op)
    v = em.get(op.operands[0])
    t = op.operands[0].type
    lanes = [v] if isinstance(t, T.ScalarType) else [f"{v}.c[{i}]" for i in range(CT.count(t))]
    if is_f16(T.elem_type(t)):
        lanes = [f"kd_h2f({x})" for x in lanes]
    nan, inf = em.fresh(), em.fresh()
    em.line(f"bool {nan} = {' || '.join(f'isnan({x})' for x in lanes)};")
    em.line(f"bool {inf} = {' || '.join(f'isinf({x})' for x in lanes)};")
    em.open(f"if (({nan} || {inf}) && {_claim(R.FP, op.attrs['site'])}) {{")
    em.line(f"kd_err[{R.FP_TID}] = {_tid(em)};")
    em.line(f"kd_err[{R.FP_KIND}] = {nan} ? 1 : 2;")
    em.close()


def _check_record(em: FuncEmitter, op: Operation) -> None:
    _require_debug(em, op)
    rid = em.get(op.operands[0])
    tag = record_tag(op.attrs["arg"])
    # ``||`` stops before the read of an implausible id (``plausible_record_id``).
    span = f"({rid} - {RECORD_ID_MIN}ull >= {RECORD_ID_END - RECORD_ID_MIN}ull)"
    odd = f"({rid} & {RECORD_ALIGN - 1}ull)"
    em.open(f"if ({span} || {odd} || *(const unsigned long long *){rid} != {tag}ull) {{")
    em.open(f"if ({_claim(R.BOUNDS, op.attrs['site'])}) {{")
    em.line(f"kd_err[{R.BOUNDS_TID}] = {_tid(em)}; kd_err[{R.BOUNDS_IDX}] = (long long){rid};")
    em.close()
    em.line(abort(em))
    em.close()


CUDA.register("kd.check_bounds", _check_bounds)
CUDA.register("kd.check_record", _check_record)
CUDA.register("kd.check_finite", _check_finite)
