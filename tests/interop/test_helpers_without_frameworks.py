"""Helpers that need no framework: Paddle's device strings, dtype name mapping."""

import pytest

import kdsl as wp
from kdsl.errors import KdslError
from kdsl.interop.dtypes import framework_name, scalar_from_name
from kdsl.ir import types as T
from kdsl.types import class_of


def test_paddle_device_strings_need_no_paddle():
    assert wp.device_from_paddle("cpu") == "cpu"
    assert wp.device_to_paddle("cpu") == "cpu"
    with pytest.raises(RuntimeError, match="no kdsl equivalent"):
        wp.device_from_paddle("xpu:0")
    if not wp.is_cuda_available():
        with pytest.raises(KdslError, match="not available"):
            wp.device_from_paddle("gpu:0")


def test_name_mapping_is_derived_from_the_one_dtype_table():
    for t in T.SCALARS.values():
        if t is not T.BF16:  # see below
            assert scalar_from_name(class_of(t).__name__, "x") == t
    assert framework_name("torch.float32") == "float32"
    assert framework_name("paddle.bool") == "bool"
    # torch and Paddle see uint32 data as int32 (they lack it), uint8 as itself
    assert scalar_from_name(T.U32.torch, "x") == T.I32
    assert scalar_from_name(T.U8.paddle, "x") == T.U8
    with pytest.raises(TypeError, match="no kdsl equivalent for zero-copy interop"):
        scalar_from_name("bfloat16", "torch dtype torch.bfloat16")
    with pytest.raises(TypeError, match="no kdsl equivalent"):
        scalar_from_name("complex128", "x")
