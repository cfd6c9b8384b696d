"""The cuda backend emits a feature's code only for a module whose feature analysis lists it.

Each kernel below uses one optional feature; its CUDA C must hold that feature's code
and no code of the features it does not use. No GPU needed (NVRTC only, when present).
"""

from __future__ import annotations

import pytest

import kdsl as wp
from kdsl.backends.cuda import helpers
from kdsl.backends.cuda.emitter import Source
from kdsl.backends.cuda.lower import generate
from kdsl.errors import KdslError
from kdsl.ir import types as T
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline
from kdsl.passes.features import analyze_features

#: Feature -> text its code shows in a CUDA C unit (a helper, a call, a #line file).
MARKERS = {
    "f16": "kd_f16",
    "print": "printf(",
    "atomic.add": "kd_atomic_add",
    "math.tan": "tanf(",
    "vectors": "kd_vec",
    "structs": "struct k_",
    "stdlib.random": "random.py",
    "stdlib.noise": "noise.py",
}


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def uses_f16(h: wp.array(dtype=wp.float16), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = float(h[i])


@wp.kernel
def uses_print(y: wp.array(dtype=float)):
    i = wp.tid()
    print(y[i])


@wp.kernel
def uses_atomics(c: wp.array(dtype=int)):
    i = wp.tid()
    wp.atomic_add(c, 0, i)


@wp.kernel
def uses_tan(y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.tan(y[i])


@wp.kernel
def uses_vectors(v: wp.array(dtype=wp.vec3), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.length(v[i])


@wp.struct
class FeatureProbe:
    x: float
    m: float


@wp.kernel
def uses_structs(p: wp.array(dtype=FeatureProbe), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = p[i].x * p[i].m


@wp.kernel
def uses_random(y: wp.array(dtype=float)):
    i = wp.tid()
    s = wp.rand_init(42, i)
    y[i] = wp.randf(s)


@wp.kernel
def uses_noise(y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.noise(wp.uint32(7), y[i])


#: Feature -> a kernel that uses it (noise draws its gradients from random).
KERNELS = {
    "f16": uses_f16,
    "print": uses_print,
    "atomic.add": uses_atomics,
    "math.tan": uses_tan,
    "vectors": uses_vectors,
    "structs": uses_structs,
    "stdlib.random": uses_random,
    "stdlib.noise": uses_noise,
}


def _module(kernel, pipeline: str = DEFAULT_PIPELINE):
    m = kernel.build_module()
    run_pipeline(m, pipeline)
    return m


def _unit(kernel) -> tuple[frozenset[str], str]:
    m = _module(kernel)
    return analyze_features(m).names, generate(m, [kernel.key]).text


def test_saxpy_uses_no_optional_feature_and_holds_no_code_for_one():
    names, src = _unit(saxpy)
    assert names == frozenset()
    for marker in MARKERS.values():
        assert marker not in src
    assert "atomic" not in src and "#include" not in src and "kd_err" not in src


@pytest.mark.parametrize("feature", sorted(KERNELS))
def test_a_kernel_gets_the_code_of_its_features_only(feature):
    names, src = _unit(KERNELS[feature])
    assert feature in names
    for other, marker in MARKERS.items():
        assert (marker in src) == (other in names), (other, marker)


def test_debug_checks_are_features_and_take_the_error_record():
    m = _module(saxpy, DEFAULT_PIPELINE + ",bounds-check,fp-check")
    names = analyze_features(m).names
    assert {"check.bounds", "check.finite"} <= names
    assert "kd_err" in generate(m, [saxpy.key], debug=True).text


def test_a_piece_of_a_feature_the_analysis_does_not_list_is_refused():
    src = Source(_module(saxpy), {})
    with pytest.raises(KdslError, match="feature 'f16'"):
        helpers.need_f16(src)
    with pytest.raises(KdslError, match="feature 'vectors'"):
        src.ctype(T.VectorType(3, T.F32))
    assert not src.uses_f16 and Source(_module(uses_f16), {}).uses_f16


def test_feature_units_compile():
    nvrtc_lib = pytest.importorskip("cupy_backends.cuda.libs.nvrtc")
    assert nvrtc_lib is not None
    from kdsl.backends.cuda import nvrtc

    units = [_unit(k)[1] for k in KERNELS.values()]
    nvrtc.compile_source(
        "".join(f"namespace u{i} {{\n{u}}}\n" for i, u in enumerate(units)), "sm_90"
    )
