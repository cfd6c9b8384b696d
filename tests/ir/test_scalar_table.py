"""The scalar table (``kdsl.ir.types``): each row's facts, checked against their sources of truth.

NumPy, ``struct``, LLVM (through llvmlite), NVRTC, DLPack (NumPy's own capsules), the
XLA FFI header JAX ships, and torch and JAX themselves, each where importable.
"""

from __future__ import annotations

import ctypes
import pickle
import re
import struct

import numpy as np
import pytest

import kdsl as wp
from kdsl.ir import types as T
from kdsl.types import SCALAR_CLASSES, class_of

SCALARS = list(T.SCALARS.values())
ids = [t.name for t in SCALARS]
#: The rows NumPy has a type for (bfloat16 is stored as uint16: see test_bfloat16_row).
NUMERIC = [t for t in SCALARS if t is not T.BF16]
nids = [t.name for t in NUMERIC]


@pytest.mark.parametrize("t", SCALARS, ids=ids)
def test_one_object_per_type(t):
    assert getattr(T, t.name.upper()) is t  # T.BOOL, T.I8 ... name the right rows
    assert T.ScalarType(t.kind, t.bits) is t
    assert pickle.loads(pickle.dumps(t)) is t
    assert T.SCALARS[t.name] is t and str(t) == t.name
    assert repr(t) == f"ScalarType(kind='{t.kind}', bits={t.bits})"


def test_unknown_scalar_is_an_error():
    with pytest.raises(ValueError, match="no float scalar of 128 bits"):
        T.ScalarType("float", 128)


@pytest.mark.parametrize("t", NUMERIC, ids=nids)
def test_numpy_and_struct(t):
    assert t.np_dtype.itemsize * 8 == t.bits
    assert t.np_dtype.kind == {"bool": "b", "int": "i", "uint": "u", "float": "f"}[t.kind]
    assert struct.calcsize("<" + t.struct) == t.np_dtype.itemsize
    assert np.dtype("<" + t.struct) == t.np_dtype
    assert T.scalar_from_numpy(t.np_dtype) is t and T.scalar_from_numpy(t.np_dtype.type) is t


@pytest.mark.parametrize("t", NUMERIC, ids=nids)
def test_public_names(t):
    cls = SCALAR_CLASSES[t]
    assert class_of(t) is cls and getattr(wp, t.np_dtype.name) is cls  # wp.float32, as Warp
    if t.suffix:
        assert getattr(wp, f"vec3{t.suffix}") is wp.vector(3, cls)


@pytest.mark.parametrize("t", SCALARS, ids=ids)
def test_llvm_type(t):
    llvm = pytest.importorskip("llvmlite.binding")
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    td = llvm.Target.from_default_triple().create_target_machine().target_data
    add = "fadd" if t.is_float else "add"  # parses only for a float (int) type
    mod = llvm.parse_assembly(
        f"@g = global {t.llvm} zeroinitializer\n"
        f"define {t.llvm} @f({t.llvm} %a) {{\n  %r = {add} {t.llvm} %a, %a\n  ret {t.llvm} %r\n}}"
    )
    size = td.get_abi_size(mod.get_global_variable("g").global_value_type)
    assert size == t.np_dtype.itemsize
    from kdsl.backends.cpu import types as LT

    assert str(LT.scalar_type(t)) == t.llvm


def test_c_spellings_compile_with_nvrtc():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc

    lines = ["struct kd_f16 { unsigned short bits; };"]
    for t in SCALARS:
        c, n = t.c, t.np_dtype.itemsize
        lines.append(f'static_assert(sizeof({c}) == {n}, "{t} size");')
        if t.is_int:
            less = "<" if t.is_signed else ">"
            lines.append(f'static_assert(({c})-1 {less} ({c})0, "{t} sign");')
            lines.append(f'static_assert(({c})0.5 == ({c})0, "{t} integral");')
        elif t.is_float and t.bits > 16:  # kd_f16 is a struct of the half's bits
            lines.append(f'static_assert(({c})0.5 != ({c})0, "{t} floating");')
    nvrtc.compile_source("\n".join(lines) + "\n", nvrtc.DEFAULT_ARCH)


@pytest.mark.parametrize("t", NUMERIC, ids=nids)
def test_dlpack_type_matches_numpys_capsules(t):
    capsule = np.zeros(1, t.np_dtype).__dlpack__()
    get = ctypes.pythonapi.PyCapsule_GetPointer
    get.restype, get.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    dl_tensor = get(capsule, b"dltensor")
    # DLTensor: void *data; DLDevice device (2 x int32); int32 ndim; DLDataType dtype.
    code, bits = (ctypes.c_uint8 * 2).from_address(dl_tensor + 20)
    assert t.dlpack == (code, bits)


def test_xla_ffi_codes_match_the_header_jax_ships():
    jax_ffi = pytest.importorskip("jax.ffi")
    header = f"{jax_ffi.include_dir()}/xla/ffi/api/c_api.h"
    with open(header) as f:
        codes = dict(re.findall(r"XLA_FFI_DataType_(\w+) = (\d+)", f.read()))
    for t in SCALARS:
        kind = {"int": "S", "uint": "U", "float": "F", "bfloat": "BF"}
        xla = "PRED" if t.is_bool else kind[t.kind] + str(t.bits)
        assert t.xla_ffi == int(codes[xla]), t


def test_framework_names():
    """torch/Paddle names: the same bits, signed where torch lacks the unsigned type."""
    for t in NUMERIC:
        twin = T.scalar_from_numpy(np.dtype(t.torch))
        assert twin.bits == t.bits and t.paddle == t.torch
        assert twin is t or (t.kind == "uint" and twin.kind == "int")
    jnp = pytest.importorskip("jax.numpy")
    for t in NUMERIC:
        assert np.dtype(getattr(jnp, t.jax)) == t.np_dtype
    assert np.dtype(jnp.bfloat16).itemsize == 2 and jnp.bfloat16.__name__ == "bfloat16"
    torch = pytest.importorskip("torch")
    for t in SCALARS:
        assert getattr(torch, t.torch).itemsize == t.np_dtype.itemsize


def test_bfloat16_row():
    """bfloat16 is a storage type: 16 bits held as NumPy's uint16, Warp's name."""
    t = T.BF16
    assert (t.kind, t.bits, t.name) == ("bfloat", 16, "bf16")
    assert t.np_dtype == np.uint16 and struct.calcsize("<" + t.struct) == 2
    assert T.scalar_from_numpy(np.uint16) is T.U16  # uint16 data stays uint16
    assert class_of(t) is wp.bfloat16 and SCALAR_CLASSES[t] is wp.bfloat16
    assert t.dlpack == (4, 16)  # kDLBfloat
    assert (t.torch, t.jax) == ("bfloat16", "bfloat16") and not t.suffix
