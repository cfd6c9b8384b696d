"""kdsl.render.UsdRenderer writes a USD stage with Warp's calls; bad input is refused."""

import sys

import numpy as np
import pytest

import kdsl as wp
import kdsl.render
from kdsl.errors import KdslCapabilityError, KdslTypeError, KdslValueError
from kdsl.render import RenderDependencyError

pxr = pytest.importorskip("pxr", reason="needs usd-core (the usd extra)")
from pxr import Usd, UsdGeom  # noqa: E402


def _write(path, frames=3):
    r = kdsl.render.UsdRenderer(str(path), up_axis="Z", fps=30, scaling=2.0)
    r.render_ground(size=5.0)
    tpl = r.render_box("crate", None, None, (0.5, 0.5, 0.5), is_template=True)
    for f in range(frames):
        r.begin_frame(f / 30.0)
        pts = wp.array(np.arange(12.0).reshape(4, 3) + f, dtype=wp.vec3)  # a kdsl array
        r.render_points("pts", pts, radius=0.1, colors=(1.0, 0.0, 0.0))
        r.render_points("dots", pts.numpy(), radius=np.full(4, 0.2), as_spheres=False)
        r.render_mesh("tri", [[0, 0, 0], [1, 0, 0], [0, 1, f]], np.array([0, 1, 2]),
                      colors=(0.2, 0.4, 0.6))  # fmt: skip
        r.render_sphere("ball", wp.vec3(0.0, 0.0, float(f)), wp.quat_identity(), 0.5)
        q = wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), 0.5)
        r.render_capsule("cap", (0, 0, 0), q, 0.1, 0.5, up_axis=2, color=(0, 1, 0))
        r.render_line_strip("rope", np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]]), color=(1, 1, 1))
        r.add_shape_instance("crate_1", tpl, None, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
        r.end_frame()
    assert r.save() is True
    return r


def test_stage_reopens_with_prims_and_time_samples(tmp_path):
    path = tmp_path / "scene.usda"
    _write(path)
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert stage.GetFramesPerSecond() == 30.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 2.0)
    assert stage.GetDefaultPrim().GetPath() == "/root"
    kinds = {str(p.GetPath()): p.GetTypeName() for p in stage.Traverse()}
    for path_, kind in [("/root/ground", "Mesh"), ("/root/pts", "PointInstancer"),
                        ("/root/dots", "Points"), ("/root/tri", "Mesh"), ("/root/ball", "Sphere"),
                        ("/root/cap", "Capsule"), ("/root/rope", "PointInstancer"),
                        ("/root/crate_1", "Cube")]:  # fmt: skip
        assert kinds.get(path_) == kind, path_
    pos = UsdGeom.PointInstancer(stage.GetPrimAtPath("/root/pts")).GetPositionsAttr()
    assert pos.GetTimeSamples() == [0.0, 1.0, 2.0]
    np.testing.assert_allclose(np.array(pos.Get(2.0)), np.arange(12.0).reshape(4, 3) + 2)
    tri = UsdGeom.Mesh(stage.GetPrimAtPath("/root/tri"))
    assert list(tri.GetFaceVertexIndicesAttr().Get(0.0)) == [0, 1, 2]
    assert tri.GetPointsAttr().Get(2.0)[2][2] == 2.0
    ops = UsdGeom.Xformable(stage.GetPrimAtPath("/root/ball")).GetOrderedXformOps()
    assert tuple(ops[0].Get(1.0)) == (0.0, 0.0, 1.0)
    # The box template's half-extents scale each instance (a size-2 cube).
    crate = UsdGeom.Xformable(stage.GetPrimAtPath("/root/crate_1")).GetOrderedXformOps()
    assert tuple(crate[2].Get(0.0)) == (0.5, 0.5, 0.5)
    # Two rope segments, each a capsule scaled to its length along the rotated z axis.
    rope = UsdGeom.PointInstancer(stage.GetPrimAtPath("/root/rope"))
    np.testing.assert_allclose(np.array(rope.GetScalesAttr().Get(0.0))[:, 2], [1.0, 1.0])
    np.testing.assert_allclose(np.array(rope.GetPositionsAttr().Get(0.0)),
                               [[0.5, 0, 0], [1, 0.5, 0]])  # fmt: skip


def test_bad_input_is_refused_at_the_call(tmp_path):
    r = kdsl.render.UsdRenderer(str(tmp_path / "bad.usda"))
    with pytest.raises(KdslTypeError, match=r"points must be n 3-vectors.*\(4, 2\)") as e:
        r.render_points("p", np.zeros((4, 2)), radius=0.1)
    assert e.value.loc.file == __file__  # the user's line, not kdsl's
    with pytest.raises(KdslTypeError, match=r"indices must lie in \[0, 3\)"):
        r.render_mesh("m", np.zeros((3, 3)), [0, 1, 3])
    with pytest.raises(KdslTypeError, match="multiple of 3"):
        r.render_mesh("m", np.zeros((3, 3)), [0, 1])
    with pytest.raises(KdslTypeError, match=r"colors must be one RGB color"):
        r.render_points("p", np.zeros((4, 3)), radius=0.1, colors=np.zeros((2, 3)))
    with pytest.raises(KdslTypeError, match="rot must have 4 components"):
        r.render_sphere("s", (0, 0, 0), (0, 0, 1), 1.0)
    with pytest.raises(KdslValueError, match="not a shape this renderer made"):
        r.add_shape_instance("i", "/root/nothing", None, (0, 0, 0), (0, 0, 0, 1))
    with pytest.raises(KdslValueError, match="up_axis must be one of X, Y, Z"):
        kdsl.render.UsdRenderer(str(tmp_path / "w.usda"), up_axis="W")
    with pytest.raises(KdslValueError, match=r"a file path or a pxr\.Usd\.Stage"):
        kdsl.render.UsdRenderer(42)


def test_without_usd_core_the_error_names_the_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "pxr", None)  # import pxr now raises ImportError
    with pytest.raises(RenderDependencyError, match=r"pip install 'kdsl\[usd\]'") as e:
        kdsl.render.UsdRenderer(str(tmp_path / "x.usda"))
    assert isinstance(e.value, ImportError)  # code that catches Warp's ImportError still works


def test_opengl_renderer_is_refused_with_the_alternatives():
    with pytest.raises(KdslCapabilityError, match=r"UsdRenderer.*--render") as e:
        kdsl.render.OpenGLRenderer(title="demo", headless=True)
    assert e.value.loc.file == __file__
