"""A scene compiles only what it needs: no adjoint when forward-only, no geometry code."""

from kdsl.scenes.measure import compile_info, make_scene, run_scene

#: Feature names that would mean geometry code (handles, spatial library code).
GEOMETRY = {"handles", "stdlib.spatial", "stdlib.transform", "stdlib.quat"}


def test_forward_only_scene_compiles_no_adjoint():
    scene = make_scene("chain", "f32", "rk4", count=4)
    infos = compile_info(scene, 1e-3)
    assert {k.kernel.split("_")[0] for k in infos} >= {"spring", "axpy", "rk4"}
    assert not any(k.adjoint for k in infos)
    assert all("adjoint" not in k.features and "tapes" not in k.features for k in infos)


def test_scene_without_geometry_emits_no_geometry_code():
    from kdsl.backends.registry import get_backend
    from kdsl.compiler import lower

    scene = make_scene("heat", "f32", "explicit_euler", grid=4)
    for k in compile_info(scene, 1e-4):
        assert not GEOMETRY & set(k.features), k
    code = lower(get_backend("cpu"), scene.k.laplacian, "llvm-ir-unopt")
    assert "mesh" not in code.lower() and "bvh" not in code.lower()


def test_info_reports_ops_size_and_time():
    scene = make_scene("particles", "f64", "symplectic_euler", count=4)
    (k,) = compile_info(scene, 1e-2)  # the seeds' fused integrate kernel only
    assert k.kernel.startswith("integrate") and k.ops > 5
    # No binary size when another test compiled the same IR (the in-memory cache hit).
    assert k.code_bytes is None or k.code_bytes > 0
    assert k.compile_s > 0
    assert "vectors" in k.features and "f64" in k.features and "f16" not in k.features
    assert run_scene(scene, 1e-2, 3).kernels_compiled == 0  # compiled already


def test_differentiable_scene_builds_adjoints_only_for_the_taped_kernels():
    scene = make_scene("throw", "f32", "rk4", count=2)
    infos = compile_info(scene, 0.25)
    adjoint = {k.kernel.split("__")[0].rsplit("_", 1)[0] for k in infos if k.adjoint}
    assert adjoint == {"throw_step", "miss_loss"}  # not the descent's update kernel
    assert any(k.kernel.startswith("descend") and not k.adjoint for k in infos)
