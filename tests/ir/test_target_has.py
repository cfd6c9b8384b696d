"""``kd.target_has`` (``kdsl.ir.ops_target``): a per-backend constant no pass folds.

The interpreter and the cpu backend take the ``"wide-tree"`` path, the cuda backend
does not (its CUDA C holds ``false``, and NVRTC drops what stands behind it: the mesh
closest-point kernel's PTX keeps the binary walk alone); an unknown feature is a
located verifier error."""

from __future__ import annotations

import re

import pytest

import kdsl as wp
from kdsl.errors import KdslVerifyError
from kdsl.frontend.builtins_target import TARGET_HAS_WIDE_TREE
from kdsl.ir import parse_module, print_module
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline


@wp.kernel
def flag_kernel(out: wp.array(dtype=int)):
    out[0] = int(TARGET_HAS_WIDE_TREE())


@wp.kernel
def closest_kernel(mesh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, p[i], 10.0)
    out[i] = q.u + float(q.face)


def _optimized(kernel):
    m = kernel.build_module()
    run_pipeline(m, DEFAULT_PIPELINE)
    return m


@pytest.mark.parametrize("backend", ["interp", "cpu"])
def test_host_backends_take_the_wide_tree(backend):
    out = wp.zeros(1, dtype=int)
    wp.launch(flag_kernel, dim=1, inputs=[out], backend=backend)
    assert out.numpy()[0] == 1


def test_no_pass_folds_it():
    text = print_module(_optimized(flag_kernel))
    assert re.search(r'kd\.target_has \{feature = "wide-tree"\}', text), text


def test_cuda_lowers_it_to_false_and_leaves_the_wide_walk_out():
    pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    from kdsl.backends.cuda import nvrtc
    from kdsl.backends.cuda.lower import generate

    src = generate(_optimized(flag_kernel), [flag_kernel.key]).text
    assert "false" in src
    ptx = nvrtc.compile_source(generate(_optimized(closest_kernel), [closest_kernel.key]).text,
                               "sm_90").ptx  # fmt: skip
    # 2,279 lines with the binary walk alone, 4,946 with the wide walk compiled in
    assert len(ptx.splitlines()) < 3500


def test_an_unknown_feature_is_a_verifier_error():
    text = (
        'func.func @f() -> (bool) {kind = "func"} {\n'
        '  %0 = kd.target_has {feature = "warp-drive"} : bool\n'
        "  func.return %0\n}\n"
    )
    with pytest.raises(KdslVerifyError, match="feature must be one of"):
        parse_module(text, file="t.kir")
