"""``kdsl.compiler.record_compiles``: one record per kernel the driver compiles."""

import numpy as np

import kdsl as wp
from kdsl.compiler import record_compiles


@wp.kernel
def _scale(a: wp.array(dtype=wp.float32), s: wp.float32):
    i = wp.tid()
    a[i] = a[i] * s


def test_records_each_compile_with_features_and_no_adjoint():
    from kdsl.runtime.launch import forget

    forget(_scale)  # compiled by another test of this worker: compile it again
    a = wp.array(np.ones(4, dtype=np.float32))
    with record_compiles() as records:
        wp.launch(_scale, dim=4, inputs=[a, 2.0])
    (r,) = [r for r in records if r.symbol.startswith("_scale")]
    assert r.backend == "cpu" and r.op_count > 3 and r.seconds > 0
    assert not r.adjoint and "f16" not in r.features
    assert r.code_bytes is None or r.code_bytes > 0
    assert np.allclose(a.numpy(), 2.0)


def test_adjoint_compiles_are_recorded_as_adjoints():
    a = wp.array(np.ones(4, dtype=np.float32), requires_grad=True)
    with record_compiles() as records:
        tape = wp.Tape()
        with tape:
            wp.launch(_scale, dim=4, inputs=[a, 3.0])
        tape.backward(grads={a: wp.array(np.ones(4, dtype=np.float32))})
    assert any(r.adjoint for r in records)


def test_nothing_is_recorded_outside_a_block():
    with record_compiles() as records:
        pass
    wp.launch(_scale, dim=4, inputs=[wp.zeros(4, dtype=wp.float32), 1.0])
    assert records == []
