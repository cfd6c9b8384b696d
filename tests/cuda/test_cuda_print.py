"""print()/printf() on the cuda backend: escaped format literals (NVRTC) and GPU output."""

from __future__ import annotations

import ctypes
import re

import pytest

pytest.importorskip("cupy_backends.cuda.libs.nvrtc")

import kdsl as wp
from kdsl.backends.cuda import nvrtc
from kdsl.backends.cuda.lower import generate
from kdsl.backends.cuda.printing import c_string_literal
from kdsl.ir.ops_print import c_format
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline

NASTY = 'q="x" \\ */ /* ??/ ??= 100%% é\n%d %s\t%g\n'


@wp.kernel
def nasty(i: int, x: float):
    wp.printf(NASTY, i, x > 0.0, x)
    print("vec", wp.vec2(x, -x), "flag", x < 0.0)


def _unescape(literal: str) -> bytes:
    """The bytes a C compiler reads from one of our literals (plain bytes, octal escapes)."""
    assert literal[0] == literal[-1] == '"'
    body = literal[1:-1]
    out, k = bytearray(), 0
    while k < len(body):
        if body[k] == "\\":
            out.append(int(body[k + 1 : k + 4], 8))
            k += 4
        else:
            out.append(ord(body[k]))
            k += 1
    return bytes(out)


def test_string_literals_escape_everything_risky():
    text = c_format(NASTY)
    lit = c_string_literal(text)
    assert _unescape(lit) == text.encode()
    inner = lit[1:-1]
    for risky in ('"', "\\\\", "*/", "/*", "??", "\n", "\t"):
        assert risky not in inner


def test_generated_printf_compiles_and_holds_only_escaped_text():
    m = nasty.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    code = generate(m, [nasty.key]).text
    calls = [line for line in code.splitlines() if "printf(" in line]
    assert len(calls) == 2
    literal = re.search(r'printf\(("(?:[^"\\]|\\[0-7]{3})*")', calls[0]).group(1)
    assert _unescape(literal) == c_format(NASTY).encode()
    assert 'q="x"' not in code and "*/ /*" not in code
    nvrtc.compile_source(code, "sm_90")


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA GPU")
def test_device_printf_output(capfd):
    wp.launch(nasty, 1, [7, 1.5], device="cuda:0")
    wp.synchronize()
    ctypes.CDLL(None).fflush(None)
    out = capfd.readouterr().out
    assert out == 'q="x" \\ */ /* ??/ ??= 100% é\n7 True\t1.5\nvec 1.5 -1.5  flag False\n'
