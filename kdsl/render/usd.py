"""``kdsl.render.UsdRenderer``: Warp's ``warp.render.UsdRenderer`` API on usd-core (docs/render.md).

It writes a USD stage: everything under an ``/root`` transform (scaled by
``scaling``), a dome and a distant light, the stage's up axis and frame rate. Each
``render_*`` call defines (first call) or updates (later calls) one prim under
``/root``, writing the values that change as time samples at the current frame,
``round(time * fps)`` from ``begin_frame(time)``. Shapes made with
``is_template=True`` are class prims under ``/root/_template_shapes``, instanced by
``add_shape_instance``. usd-core (``pip install 'kdsl[usd]'``) is imported only when a
renderer is built.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from kdsl.errors import KdslError, KdslValueError
from kdsl.render import inputs
from kdsl.render.inputs import RenderDependencyError, user_loc

UP_AXES = ("X", "Y", "Z")
_Z = np.array([0.0, 0.0, 1.0])


def _pxr() -> Any:
    """The ``pxr`` package, or a ``RenderDependencyError`` saying how to install it."""
    try:
        import pxr
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, Vt  # noqa: F401
    except ImportError:
        raise RenderDependencyError(
            "kdsl.render.UsdRenderer needs usd-core (the pxr package): "
            "pip install 'kdsl[usd]' (or pip install usd-core)", user_loc(),
        ) from None  # fmt: skip
    return pxr


def _vec3f_array(values: np.ndarray) -> Any:
    from pxr import Vt

    return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32).reshape(-1, 3))


class UsdRenderer:
    """Write an animated USD stage with Warp's ``UsdRenderer`` calls.

    Args:
        stage: a file path (a new stage is created there) or a ``pxr.Usd.Stage``.
        up_axis: ``"X"``, ``"Y"`` or ``"Z"``, the stage's up axis.
        fps: frames per second; ``begin_frame(t)`` writes at frame ``round(t * fps)``.
        scaling: a uniform scale on ``/root`` (everything drawn).
    """

    def __init__(
        self, stage: Any, up_axis: str = "Y", fps: float = 60, scaling: float = 1.0
    ) -> None:
        pxr = _pxr()
        Usd, UsdGeom = pxr.Usd, pxr.UsdGeom
        axis = str(up_axis).upper()
        if axis not in UP_AXES:
            raise KdslValueError(f"up_axis must be one of X, Y, Z, not {up_axis!r}", user_loc())
        if isinstance(stage, (str, os.PathLike)):
            path = os.fspath(stage)
            try:
                stage = Usd.Stage.CreateNew(path)
            except Exception as e:  # pxr raises Tf.ErrorException
                raise KdslError(f"cannot create the USD stage {path!r}: {e}", user_loc()) from None
        elif not isinstance(stage, Usd.Stage):
            raise KdslValueError(
                f"stage must be a file path or a pxr.Usd.Stage, got {type(stage).__name__}",
                user_loc(),
            )
        self.stage = stage
        self.up_axis = axis
        self.fps = float(fps)
        self.time = 0.0
        # Warp's renderer carries these switches for its callers; they change nothing here.
        self.draw_points, self.draw_springs, self.draw_triangles = True, False, False
        #: Template prim path -> (schema class, extra scale) for ``add_shape_instance``.
        self._templates: dict[str, tuple[Any, tuple[float, float, float]]] = {}

        self.root = UsdGeom.Xform.Define(stage, "/root")
        self.root.ClearXformOpOrder()
        self.root.AddScaleOp().Set(pxr.Gf.Vec3d(float(scaling)), 0.0)
        stage.SetDefaultPrim(self.root.GetPrim())
        stage.SetStartTimeCode(0.0)
        stage.SetEndTimeCode(0.0)
        stage.SetFramesPerSecond(self.fps)
        stage.SetTimeCodesPerSecond(self.fps)
        UsdGeom.SetStageUpAxis(stage, getattr(UsdGeom.Tokens, axis.lower()))
        self._add_lights(pxr)

    def _add_lights(self, pxr: Any) -> None:
        UsdLux, Sdf = pxr.UsdLux, pxr.Sdf
        dome = UsdLux.DomeLight.Define(self.stage, "/dome_light")
        dome.AddRotateXYZOp().Set((-90.0, -30.0, 0.0))
        dome.CreateIntensityAttr().Set(1.0)
        dome.CreateExposureAttr().Set(9.0)
        dome.GetPrim().CreateAttribute("visibleInPrimaryRay", Sdf.ValueTypeNames.Bool).Set(False)
        sun = UsdLux.DistantLight.Define(self.stage, "/distant_light")
        sun.AddRotateXYZOp().Set((-35.0, 45.0, 0.0))
        sun.CreateIntensityAttr().Set(1.0)
        sun.CreateExposureAttr().Set(10.0)

    # ------------------------------------------------------------------ frames

    def begin_frame(self, time: float) -> None:
        """Write what follows at frame ``round(time * fps)`` (``time`` in seconds)."""
        self.time = float(round(float(time) * self.fps))
        if self.time > self.stage.GetEndTimeCode():
            self.stage.SetEndTimeCode(self.time)

    def end_frame(self) -> None:
        """End the frame (nothing to flush: USD writes happen as they are made)."""

    def save(self) -> bool:
        """Write the stage to its file; True on success (a ``KdslError`` says why not)."""
        try:
            self.stage.Save()
        except Exception as e:
            raise KdslError(f"cannot save the USD stage: {e}", user_loc()) from None
        return True

    # ------------------------------------------------------------------ prim helpers

    def _path(self, name: str, parent_body: str | None = None) -> Any:
        path = self.root.GetPath()
        if parent_body is not None:
            path = path.AppendChild(parent_body)
        return path.AppendChild(name)

    def _define(self, schema: Any, kind: str, name: str, parent_body: str | None,
                is_template: bool) -> tuple[Any, Any, bool]:  # fmt: skip
        """(prim of ``schema``, path to return, created?) for a named shape.

        A template is a class prim (instanceable scope) holding the shape as its child
        ``kind``; ``add_shape_instance`` references it.
        """
        from pxr import Sdf, UsdGeom

        if is_template:
            top = self.root.GetPath().AppendChild("_template_shapes").AppendChild(name)
            scope = UsdGeom.Scope.Define(self.stage, top).GetPrim()
            scope.SetInstanceable(True)
            scope.SetSpecifier(Sdf.SpecifierClass)
            path = top.AppendChild(kind)
        else:
            top = path = self._path(name, parent_body)
        prim = schema.Get(self.stage, path)
        created = not prim
        if created:
            prim = schema.Define(self.stage, path)
            self._xform_ops(prim)
        return prim, top, created

    @staticmethod
    def _xform_ops(prim: Any) -> None:
        from pxr import UsdGeom

        xf = UsdGeom.Xformable(prim)
        xf.ClearXformOpOrder()
        xf.AddTranslateOp()
        xf.AddOrientOp()
        xf.AddScaleOp()

    def _place(self, prim: Any, pos: Any, rot: Any, scale: Any, time: float | None = None) -> None:
        """Set translate (``pos``), orient (``rot``, x y z w) and scale at ``time``."""
        from pxr import Gf, UsdGeom

        t = self.time if time is None else time
        ops = UsdGeom.Xformable(prim).GetOrderedXformOps()
        p = inputs.vector(pos, 3, "pos")
        q = inputs.vector(rot, 4, "rot")
        s = inputs.vector(scale, 3, "scale")
        ops[0].Set(Gf.Vec3d(*map(float, p)), t)
        ops[1].Set(Gf.Quatf(float(q[3]), float(q[0]), float(q[1]), float(q[2])), t)
        ops[2].Set(Gf.Vec3f(*map(float, s)), t)

    def _finish(self, prim: Any, kind_schema: Any, top: Any, color: Any, visible: bool,
                custom_scale: Any = (1.0, 1.0, 1.0)) -> Any:  # fmt: skip
        """Color, visibility and the template record shared by every shape."""
        from pxr import Gf

        if color is not None:
            c = inputs.vector(color, 3, "color")
            prim.GetDisplayColorAttr().Set([Gf.Vec3f(*map(float, c))], self.time)
        prim.GetVisibilityAttr().Set("inherited" if visible else "invisible", self.time)
        self._templates[top.name] = (kind_schema, tuple(float(x) for x in custom_scale))
        return top

    def _solid(self, schema: Any, kind: str, name: str, pos: Any, rot: Any,
               parent_body: str | None, is_template: bool, color: Any, visible: bool,
               **sizes: Any) -> Any:  # fmt: skip
        if not is_template:  # checked before the stage changes
            inputs.vector(pos, 3, "pos"), inputs.vector(rot, 4, "rot")
        prim, top, _ = self._define(schema, kind, name, parent_body, is_template)
        for attr, value in sizes.items():
            getattr(prim, f"Create{attr}Attr")().Set(value, self.time)
        if not is_template:
            self._place(prim, pos, rot, (1.0, 1.0, 1.0))
        return self._finish(prim, schema, top, color, visible)

    # ------------------------------------------------------------------ shapes

    def register_body(self, body_name: str) -> None:
        """Define a transform ``/root/<body_name>`` that shapes can name as ``parent_body``."""
        from pxr import UsdGeom

        self._xform_ops(UsdGeom.Xform.Define(self.stage, self._path(body_name)))

    def render_sphere(self, name: str, pos: Any, rot: Any, radius: float,
                      parent_body: str | None = None, is_template: bool = False,
                      color: Any = None, visible: bool = True) -> Any:  # fmt: skip
        """A sphere of ``radius`` at ``pos``; returns its prim path."""
        from pxr import UsdGeom

        return self._solid(UsdGeom.Sphere, "sphere", name, pos, rot, parent_body, is_template,
                           color, visible, Radius=float(radius))  # fmt: skip

    def _round_solid(self, schema: Any, kind: str, name: str, pos: Any, rot: Any,
                     radius: float, half_height: float, parent_body: str | None,
                     is_template: bool, up_axis: int, color: Any, visible: bool) -> Any:  # fmt: skip
        if up_axis not in (0, 1, 2):
            raise KdslValueError(f"up_axis must be 0, 1 or 2 (X, Y, Z), not {up_axis!r}",
                                 user_loc())  # fmt: skip
        return self._solid(schema, kind, name, pos, rot, parent_body, is_template, color,
                           visible, Radius=float(radius), Height=float(2.0 * half_height),
                           Axis=UP_AXES[up_axis])  # fmt: skip

    def render_capsule(self, name: str, pos: Any, rot: Any, radius: float, half_height: float,
                       parent_body: str | None = None, is_template: bool = False,
                       up_axis: int = 1, color: Any = None, visible: bool = True) -> Any:  # fmt: skip
        """A capsule along axis ``up_axis`` (0, 1, 2); returns its prim path."""
        from pxr import UsdGeom

        return self._round_solid(UsdGeom.Capsule, "capsule", name, pos, rot, radius,
                                 half_height, parent_body, is_template, up_axis, color, visible)  # fmt: skip

    def render_cylinder(self, name: str, pos: Any, rot: Any, radius: float, half_height: float,
                        parent_body: str | None = None, is_template: bool = False,
                        up_axis: int = 1, color: Any = None, visible: bool = True) -> Any:  # fmt: skip
        """A cylinder along axis ``up_axis``; returns its prim path."""
        from pxr import UsdGeom

        return self._round_solid(UsdGeom.Cylinder, "cylinder", name, pos, rot, radius,
                                 half_height, parent_body, is_template, up_axis, color, visible)  # fmt: skip

    def render_cone(self, name: str, pos: Any, rot: Any, radius: float, half_height: float,
                    parent_body: str | None = None, is_template: bool = False,
                    up_axis: int = 1, color: Any = None, visible: bool = True) -> Any:  # fmt: skip
        """A cone along axis ``up_axis``; returns its prim path."""
        from pxr import UsdGeom

        return self._round_solid(UsdGeom.Cone, "cone", name, pos, rot, radius, half_height,
                                 parent_body, is_template, up_axis, color, visible)  # fmt: skip

    def render_box(self, name: str, pos: Any, rot: Any, extents: Any,
                   parent_body: str | None = None, is_template: bool = False,
                   color: Any = None, visible: bool = True) -> Any:  # fmt: skip
        """A box of half-extents ``extents`` (a size-2 cube scaled by them); its prim path."""
        from pxr import UsdGeom

        half = inputs.vector(extents, 3, "extents")
        prim, top, _ = self._define(UsdGeom.Cube, "cube", name, parent_body, is_template)
        if not is_template:
            self._place(prim, pos, rot, half)
        return self._finish(prim, UsdGeom.Cube, top, color, visible, custom_scale=half)

    def _quad(self, name_path: Any, corners: np.ndarray, normal: np.ndarray) -> Any:
        from pxr import UsdGeom

        mesh = UsdGeom.Mesh.Define(self.stage, name_path)
        mesh.CreateDoubleSidedAttr().Set(True)
        mesh.GetPointsAttr().Set(_vec3f_array(corners))
        mesh.GetNormalsAttr().Set(_vec3f_array(np.tile(normal, (4, 1))))
        mesh.GetFaceVertexCountsAttr().Set([4])
        mesh.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
        return mesh

    def render_plane(self, name: str, pos: Any, rot: Any, width: float, length: float,
                     color: Any = (1.0, 1.0, 1.0), color2: Any = None,
                     parent_body: str | None = None, is_template: bool = False,
                     u_scaling: float = 1.0, v_scaling: float = 1.0,
                     visible: bool = True) -> Any:  # fmt: skip
        """A double-sided quad in its local x-z plane, half-sizes ``width`` x ``length``.

        A size <= 0 means 100 (an "infinite" plane, as Warp draws it). ``color2`` and the
        texture scalings are accepted for Warp's checkerboard and ignored.
        """
        from pxr import UsdGeom

        w = float(width) if width > 0.0 else 100.0
        h = float(length) if length > 0.0 else 100.0
        corners = np.array([[-w, 0.0, -h], [w, 0.0, -h], [w, 0.0, h], [-w, 0.0, h]])
        prim, top, created = self._define(UsdGeom.Mesh, "plane", name, parent_body, is_template)
        if created:
            self._quad(prim.GetPath(), corners, np.array([0.0, 1.0, 0.0]))
        if not is_template:
            self._place(prim, pos, rot, (1.0, 1.0, 1.0), time=0.0)
        return self._finish(prim, UsdGeom.Mesh, top, None, visible)

    def render_ground(self, size: float = 100.0, plane: Any = None) -> None:
        """A ``2 size`` square ground at ``/root/ground``, normal to the up axis.

        ``plane`` (nx, ny, nz, d) instead puts it on the plane ``n . x = d``.
        """
        up = np.zeros(3)
        up[UP_AXES.index(self.up_axis)] = 1.0
        a, b = np.roll(up, 1), np.roll(up, 2)  # the two axes in the ground, right-handed
        s = float(size)
        corners = np.array([-a - b, a - b, a + b, -a + b]) * s
        normal = up
        if plane is not None:
            eq = inputs.vector(plane, 4, "plane")
            n = eq[:3] / np.linalg.norm(eq[:3])
            q = inputs.rotation_between(up, n)
            corners = inputs.quat_rotate(q, corners) + eq[3] * n
            normal = n
        self._quad(self._path("ground"), corners, normal)

    def render_mesh(self, name: str, points: Any, indices: Any, colors: Any = None,
                    pos: Any = (0.0, 0.0, 0.0), rot: Any = (0.0, 0.0, 0.0, 1.0),
                    scale: Any = (1.0, 1.0, 1.0), update_topology: bool = False,
                    parent_body: str | None = None, is_template: bool = False,
                    smooth_shading: bool = True, visible: bool = True) -> Any:  # fmt: skip
        """A triangle mesh: ``points`` (n, 3) and ``indices`` (3 per triangle).

        Points are written every frame; the triangles on the first call and when
        ``update_topology`` is set. ``colors``: one RGB or one per vertex.
        """
        from pxr import UsdGeom, Vt

        pts = inputs.points(points)
        tris = inputs.indices(indices, 3, len(pts))  # checked every call, before any write
        cols = inputs.colors(colors, len(pts))
        prim, top, created = self._define(UsdGeom.Mesh, "mesh", name, parent_body, is_template)
        if created:
            interp = "constant" if cols is None or cols.ndim == 1 else "vertex"
            UsdGeom.Primvar(prim.GetDisplayColorAttr()).SetInterpolation(interp)
        prim.GetPointsAttr().Set(_vec3f_array(pts), self.time)
        if created or update_topology:
            prim.GetFaceVertexIndicesAttr().Set(
                Vt.IntArray.FromNumpy(tris.reshape(-1).astype(np.int32)), self.time
            )
            prim.GetFaceVertexCountsAttr().Set(Vt.IntArray([3] * len(tris)), self.time)
        if cols is not None:
            prim.GetDisplayColorAttr().Set(_vec3f_array(cols), self.time)
        if not is_template:
            self._place(prim, pos, rot, scale)
        return self._finish(prim, UsdGeom.Mesh, top, None, visible, custom_scale=scale)

    def render_arrow(self, name: str, pos: Any, rot: Any, base_radius: float,
                     base_height: float, cap_radius: float | None = None,
                     cap_height: float | None = None, parent_body: str | None = None,
                     is_template: bool = False, up_axis: int = 1, color: Any = None,
                     visible: bool = True) -> Any:  # fmt: skip
        """An arrow along ``up_axis``: a cylinder shaft and a cone head; its prim path."""
        from pxr import Gf, UsdGeom

        cap_r = 1.8 * base_radius if cap_radius is None else cap_radius
        cap_h = 0.18 * base_height if cap_height is None else cap_height
        prim, top, _ = self._define(UsdGeom.Xform, "arrow", name, parent_body, is_template)
        axis = np.zeros(3)
        axis[up_axis] = 1.0
        for part, schema, r, h, mid in (
            ("base", UsdGeom.Cylinder, base_radius, base_height, 0.5 * base_height),
            ("cap", UsdGeom.Cone, cap_r, cap_h, base_height + 0.5 * cap_h),
        ):
            path = prim.GetPath().AppendChild(part)
            shape = schema.Get(self.stage, path)
            if not shape:
                shape = schema.Define(self.stage, path)
                self._xform_ops(shape)
            shape.CreateRadiusAttr().Set(float(r))
            shape.CreateHeightAttr().Set(float(h))
            shape.CreateAxisAttr().Set(UP_AXES[up_axis])
            self._place(shape, axis * mid, (0.0, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0), time=0.0)
            if color is not None:
                c = inputs.vector(color, 3, "color")
                shape.GetDisplayColorAttr().Set([Gf.Vec3f(*map(float, c))], self.time)
        if not is_template:
            self._place(prim, pos, rot, (1.0, 1.0, 1.0))
        return self._finish(prim, UsdGeom.Xform, top, None, visible)

    def render_ref(self, name: str, path: str, pos: Any, rot: Any, scale: Any,
                   color: Any = None) -> None:  # fmt: skip
        """Reference the USD file ``path`` at ``/root/<name>``, placed by pos/rot/scale."""
        from pxr import Gf, Usd, UsdGeom

        ref = UsdGeom.Xform.Get(self.stage, self._path(name))
        if not ref:
            ref = UsdGeom.Xform.Define(self.stage, self._path(name))
            ref.GetPrim().GetReferences().AddReference(os.fspath(path))
            self._xform_ops(ref)
        self._place(ref, pos, rot, scale)
        if color is not None:
            c = Gf.Vec3f(*map(float, inputs.vector(color, 3, "color")))
            walk = iter(Usd.PrimRange(ref.GetPrim()))
            for prim in walk:
                if prim.IsA(UsdGeom.Gprim):
                    UsdGeom.Gprim(prim).GetDisplayColorAttr().Set([c], self.time)
                    walk.PruneChildren()

    def add_shape_instance(self, name: str, shape: Any, body: str | None, pos: Any, rot: Any,
                           scale: Any = (1.0, 1.0, 1.0), color1: Any = None, color2: Any = None,
                           custom_index: int = -1, visible: bool = True) -> None:  # fmt: skip
        """Instance a template (the path a ``render_*(..., is_template=True)`` returned)."""
        if not visible:
            return
        key = getattr(shape, "name", str(shape).rsplit("/", 1)[-1])
        if key not in self._templates:
            raise KdslValueError(
                f"add_shape_instance: {str(shape)!r} is not a shape this renderer made "
                f"(make one with render_sphere/render_box/...(is_template=True))", user_loc(),
            )  # fmt: skip
        schema, extra = self._templates[key]
        prim = schema.Define(self.stage, self._path(name, body))
        prim.GetPrim().GetReferences().AddInternalReference(shape)
        self._xform_ops(prim)
        s = inputs.vector(scale, 3, "scale") * np.array(extra)
        self._place(prim, pos, rot, s)

    # ------------------------------------------------------------------ points and lines

    def render_points(self, name: str, points: Any, radius: Any, colors: Any = None,
                      as_spheres: bool = True, visible: bool = True) -> Any:  # fmt: skip
        """Points as instanced spheres (a PointInstancer) or as USD points; its prim path.

        ``radius``: one number or one per point; ``colors``: one RGB or one per point.
        """
        from pxr import Sdf, UsdGeom, Vt

        pts = inputs.points(points)
        r = inputs.radii(radius, len(pts))
        cols = inputs.colors(colors, len(pts))
        path = self._path(name)
        if as_spheres:
            inst = UsdGeom.PointInstancer.Get(self.stage, path)
            if not inst:
                inst = UsdGeom.PointInstancer.Define(self.stage, path)
                sphere = UsdGeom.Sphere.Define(self.stage, path.AppendChild("sphere"))
                sphere.CreateRadiusAttr().Set(1.0)
                inst.CreatePrototypesRel().SetTargets([sphere.GetPath()])
            inst.GetPositionsAttr().Set(_vec3f_array(pts), self.time)
            inst.GetScalesAttr().Set(_vec3f_array(np.repeat(r[:, None], 3, axis=1)), self.time)
            inst.GetProtoIndicesAttr().Set(Vt.IntArray(len(pts), 0), self.time)
            if cols is not None:
                interp = "constant" if cols.ndim == 1 else "vertex"
                primvar = UsdGeom.PrimvarsAPI(inst).CreatePrimvar(
                    "displayColor", Sdf.ValueTypeNames.Color3fArray, interp
                )
                primvar.Set(_vec3f_array(cols), self.time)
            prim = inst
        else:
            prim = UsdGeom.Points.Get(self.stage, path)
            if not prim:
                prim = UsdGeom.Points.Define(self.stage, path)
                UsdGeom.Primvar(prim.GetWidthsAttr()).SetInterpolation("vertex")
                interp = "constant" if cols is None or cols.ndim == 1 else "vertex"
                UsdGeom.Primvar(prim.GetDisplayColorAttr()).SetInterpolation(interp)
            prim.GetPointsAttr().Set(_vec3f_array(pts), self.time)
            prim.GetWidthsAttr().Set(Vt.FloatArray.FromNumpy((2.0 * r).astype(np.float32)),
                                     self.time)  # fmt: skip
            if cols is not None:
                prim.GetDisplayColorAttr().Set(_vec3f_array(cols), self.time)
        prim.GetVisibilityAttr().Set("inherited" if visible else "invisible", self.time)
        return prim.GetPath()

    def _segments(self, name: str, starts: np.ndarray, ends: np.ndarray, color: Any,
                  radius: float, visible: bool) -> None:  # fmt: skip
        """Line segments as capsules of ``radius`` instanced along each segment."""
        from pxr import Gf, UsdGeom, Vt

        if len(starts) == 0:
            return
        path = self._path(name)
        inst = UsdGeom.PointInstancer.Get(self.stage, path)
        capsule_path = path.AppendChild("capsule")
        if not inst:
            inst = UsdGeom.PointInstancer.Define(self.stage, path)
            capsule = UsdGeom.Capsule.Define(self.stage, capsule_path)
            capsule.CreateRadiusAttr().Set(float(radius))
            capsule.CreateHeightAttr().Set(1.0)
            capsule.CreateAxisAttr().Set("Z")
            inst.CreatePrototypesRel().SetTargets([capsule_path])
        d = ends - starts
        length = np.linalg.norm(d, axis=1)
        quats = np.array([inputs.rotation_between(_Z, v) if n > 0.0 else [0.0, 0.0, 0.0, 1.0]
                          for v, n in zip(d, length)])  # fmt: skip
        scales = np.stack([np.ones_like(length), np.ones_like(length), length], axis=1)
        inst.GetPositionsAttr().Set(_vec3f_array(0.5 * (starts + ends)), self.time)
        inst.GetOrientationsAttr().Set(Vt.QuathArray.FromNumpy(quats.astype(np.float16)), self.time)
        inst.GetScalesAttr().Set(_vec3f_array(scales), self.time)
        inst.GetProtoIndicesAttr().Set(Vt.IntArray(len(starts), 0), self.time)
        if color is not None:
            c = Gf.Vec3f(*map(float, inputs.vector(color, 3, "color")))
            UsdGeom.Capsule.Get(self.stage, capsule_path).GetDisplayColorAttr().Set([c], self.time)
        inst.GetVisibilityAttr().Set("inherited" if visible else "invisible", self.time)

    def render_line_list(self, name: str, vertices: Any, indices: Any, color: Any = None,
                         radius: float = 0.01, visible: bool = True) -> None:  # fmt: skip
        """Segments ``vertices[indices[2i]]`` to ``vertices[indices[2i+1]]`` as capsules."""
        pts = inputs.points(vertices, "vertices")
        pairs = inputs.indices(indices, 2, len(pts))
        self._segments(name, pts[pairs[:, 0]], pts[pairs[:, 1]], color, radius, visible)

    def render_line_strip(self, name: str, vertices: Any, color: Any = None,
                          radius: float = 0.01, visible: bool = True) -> None:  # fmt: skip
        """The polyline through ``vertices`` as capsules."""
        pts = inputs.points(vertices, "vertices")
        self._segments(name, pts[:-1], pts[1:], color, radius, visible)
