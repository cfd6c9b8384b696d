"""The C helpers generated code may call, each added to a module only when used.

Every function here adds one piece to a ``Source`` (with what it depends on) and
returns the name to call; a piece of a feature (``kd_f16``: ``f16``) is made only
when the module's feature analysis lists the feature. Integer helpers follow
``kdsl.ir.semantics``: division and remainder by zero give 0 and never trap,
``MIN / -1`` wraps, shifts by the width or more give 0 (or -1). Float min/max
follow IEEE 754-2019 minimumNumber / maximumNumber (NaN loses, -0.0 < +0.0), the
same rule as the cpu backend.
"""

from __future__ import annotations

from kdsl.backends.cuda import ctypes_ as CT
from kdsl.backends.cuda.emitter import Source
from kdsl.ir import types as T

_FI = "__device__ __forceinline__"


def need_f16(src: Source) -> None:
    """The ``kd_f16`` type and its conversions (PTX ``cvt``; no CUDA header needed)."""
    src.need(
        "f16",
        lambda: (
            f"""struct kd_f16 {{ unsigned short bits; }};
{_FI} float kd_h2f(kd_f16 h) {{
  float f; asm("cvt.f32.f16 %0, %1;" : "=f"(f) : "h"(h.bits)); return f;
}}
{_FI} kd_f16 kd_f2h(float f) {{
  kd_f16 h; asm("cvt.rn.f16.f32 %0, %1;" : "=h"(h.bits) : "f"(f)); return h;
}}
{_FI} kd_f16 kd_d2h(double d) {{
  kd_f16 h; asm("cvt.rn.f16.f64 %0, %1;" : "=h"(h.bits) : "d"(d)); return h;
}}"""
        ),
        "f16",
    )


def float_minmax(src: Source, which: str) -> str:
    """``kd_fmin`` / ``kd_fmax`` (float and double overloads)."""
    name = f"kd_f{which}"
    # Equal operands can only differ as -0.0 / +0.0: or-ing the bits gives -0.0 (min),
    # and-ing gives +0.0 (max).
    bitop = "|" if which == "min" else "&"
    cmp = "<" if which == "min" else ">"

    def one(ft: str, it: str, to_i: str, to_f: str) -> str:
        return (
            f"{_FI} {ft} {name}({ft} a, {ft} b) {{\n"
            f"  if (a != a) return b;\n  if (b != b) return a;\n"
            f"  if (a == b) return {to_f}(({it})({to_i}(a) {bitop} {to_i}(b)));\n"
            f"  return a {cmp} b ? a : b;\n}}"
        )

    src.need(
        name,
        lambda: (
            one("float", "int", "__float_as_int", "__int_as_float")
            + "\n"
            + one("double", "long long", "__double_as_longlong", "__longlong_as_double")
        ),
    )
    return name


def _int_template(src: Source, name: str, body: str) -> str:
    """Add ``template <typename T> T name(T a, T b)`` with C ``body`` once; gives ``name``."""
    src.need(name, lambda: f"template <typename T> {_FI} T {name}(T a, T b) {{\n{body}\n}}")
    return name


#: Division by zero gives 0, and by -1 (signed) negates in unsigned math, so MIN wraps.
_DIV_EDGES = (
    "  if (b == (T)0) return (T)0;\n"
    "  if ((T)-1 < (T)0 && b == (T)-1) return (T)(0ull - (unsigned long long)a);\n"
)


def int_div(src: Source) -> str:
    """``kd_idiv``: C division (truncating) where ``x / 0`` is 0 and ``MIN / -1`` wraps."""
    return _int_template(src, "kd_idiv", _DIV_EDGES + "  return (T)(a / b);")


def int_floordiv(src: Source) -> str:
    """``kd_ifloordiv``: floor division; ``x // 0`` is 0."""
    body = _DIV_EDGES + (
        "  T q = (T)(a / b);\n  T r = (T)(a % b);\n"
        "  if ((T)-1 < (T)0 && r != (T)0 && ((r < (T)0) != (b < (T)0))) q = (T)(q - 1);\n"
        "  return q;"
    )
    return _int_template(src, "kd_ifloordiv", body)


def int_mod(src: Source) -> str:
    """``kd_imod``: C remainder (sign of the dividend); ``x % 0`` is 0."""
    body = "  if (b == (T)0 || ((T)-1 < (T)0 && b == (T)-1)) return (T)0;\n  return (T)(a % b);"
    return _int_template(src, "kd_imod", body)


def shifts(src: Source, which: str) -> str:
    """``kd_shl`` / ``kd_shr`` with kdsl's out-of-range rule."""
    # Compared unsigned, a negative amount is huge: one test covers both ends.
    body = "  unsigned long long s = (unsigned long long)b;\n"
    if which == "shl":
        body += "  if (s >= sizeof(T) * 8) return (T)0;\n  return (T)((unsigned long long)a << s);"
    else:
        # A negative signed value shifted by the width or more gives -1 (the sign fill);
        # for a signed T, C's >> on a negative value is arithmetic in CUDA.
        body += "  if (s >= sizeof(T) * 8) return (T)(a < (T)0 ? -1 : 0);\n  return (T)(a >> s);"
    return _int_template(src, f"kd_{which}", body)


def element_ptr(src: Source, ndim: int, narrow: bool = False) -> str:
    """``kd_at<N>(array, i...)``: the address of an element (64-bit byte offsets); with
    ``narrow``, ``kd_at<N>_32``: the byte offset summed in 32-bit ``int`` and widened
    once, exact while the array spans less than 2**31 bytes (``geometry.offsets_fit``,
    checked at launch)."""
    name = f"kd_at{ndim}_32" if narrow else f"kd_at{ndim}"
    arr = src.ctype(T.ArrayType(T.F32, ndim))
    params = ", ".join(f"long long i{k}" for k in range(ndim))
    if narrow:
        off = " + ".join(f"(int)i{k} * (int)a.strides[{k}]" for k in range(ndim))
        off = f"(long long)({off})"
    else:
        off = " + ".join(f"i{k} * a.strides[{k}]" for k in range(ndim))
    src.need(
        name, lambda: f"{_FI} char *{name}(const {arr} &a, {params}) {{ return a.data + {off}; }}"
    )
    return name


def read_only_load(src: Source, t: T.Type) -> str:
    """``kd_ldg_<type>(p)``: the ``t`` at ``p`` loaded through the read-only data cache
    (``__ldg``, one per scalar component); ``t`` passes ``variants.ldg_type``."""
    c = src.ctype(t)
    if isinstance(t, T.ScalarType):
        name = f"kd_ldg_{CT.tag(t)}"
        body = (
            "return __ldg((const unsigned char *)p) != 0;"
            if t.is_bool
            else f"return __ldg((const {c} *)p);"
        )
    else:
        name = f"kd_ldg_{c}"
        elem = src.ctype(t.elem)
        load = (
            "__ldg((const unsigned char *)p + i) != 0"
            if t.elem.is_bool
            else f"__ldg((const {elem} *)p + i)"
        )
        body = f"{c} r; for (int i = 0; i < {CT.count(t)}; ++i) r.c[i] = {load}; return r;"
    src.need(name, lambda: f"{_FI} {c} {name}(const char *p) {{ {body} }}")
    return name


def const_bits(t: T.ScalarType, bits: int) -> str:
    """A float constant of ``t`` given by its IEEE bits (for inf, NaN)."""
    if t.bits == 16:
        return f"kd_f16{{{bits:#06x}}}"
    if t.bits == 32:
        return f"__int_as_float({bits:#010x})"
    return f"__longlong_as_double({bits:#018x}ll)"


def c_scalar(t: T.ScalarType) -> str:
    return CT.scalar_c(t)
