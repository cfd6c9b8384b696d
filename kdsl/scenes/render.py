"""Pictures of a scene: ``kdsl scene run NAME --render out.gif|png`` and ``--usd out.usda``.

A scene says what to draw through ``Scene.picture(x)`` (a ``Picture``: points, and
optionally triangles, line segments, spheres and a value per point for color). After
the timed run, ``record`` replays the run from the initial state and keeps ``frames``
evenly spaced pictures (so drawing never enters the timings). ``write_image`` draws
them with Pillow (no GUI toolkit): a fixed camera fitted to every frame, looking down
at the scene from above and to the side, orthographic; triangles painted back to front
with flat shading, then lines, then points and spheres as discs. ``write_usd`` writes
the same frames through ``kdsl.render.UsdRenderer`` (frame i at time code i). Files
are written to a temporary name and renamed: they appear whole or not at all.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from kdsl.scenes.binding import SceneError

#: Picture file suffix -> what is written.
IMAGE_SUFFIXES = {".gif": "every frame, animated", ".png": "the last frame"}
USD_SUFFIXES = (".usd", ".usda", ".usdc")
BACKGROUND = (246, 246, 243)
POINT_COLOR = np.array([0.85, 0.35, 0.15])
SURFACE_COLOR = np.array([0.35, 0.55, 0.90])
LINE_COLOR = np.array([0.25, 0.25, 0.30])
SPHERE_COLOR = np.array([0.55, 0.60, 0.55])
LIGHT = np.array([0.3, 0.9, 0.3]) / np.linalg.norm([0.3, 0.9, 0.3])


@dataclass
class Picture:
    """What one frame shows, in scene units (y up)."""

    points: np.ndarray  #: (n, 3) positions
    triangles: np.ndarray | None = None  #: (m, 3) indices into points: a surface
    lines: np.ndarray | None = None  #: (k, 2) indices into points: segments
    spheres: list[tuple[np.ndarray, float]] = field(default_factory=list)  #: (center, radius)
    values: np.ndarray | None = None  #: (n,) a value per point, shown as color
    show_points: bool = True  #: draw the points as discs (off for a surface)


def grid_triangles(n: int) -> np.ndarray:
    """The ``2 (n-1)^2`` triangles of an ``n x n`` grid of points numbered row by row."""
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    return np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])


def polyline(n: int) -> np.ndarray:
    """The segments joining points ``0, 1, ..., n-1`` in order."""
    i = np.arange(max(n - 1, 0))
    return np.stack([i, i + 1], 1)


def height_field(values: np.ndarray, scale: float) -> Picture:
    """An ``n x n`` grid of ``values`` (row by row) as a surface on [0, 1]^2, height ``scale v``."""
    n = math.isqrt(len(values))
    s = np.linspace(0.0, 1.0, n)
    gx, gz = np.meshgrid(s, s, indexing="ij")
    pts = np.stack([gx.ravel(), scale * values, gz.ravel()], axis=1)
    return Picture(pts, triangles=grid_triangles(n), values=values, show_points=False)


def height_scale(scene: Any, height: float = 0.3) -> float:
    """``height / max |x0|``: scalar states drawn up to ``height`` (x0: the scene's start)."""
    if not hasattr(scene, "_picture_height_scale"):
        peak = float(np.max(np.abs(scene.initial_state()[0]))) if scene.n else 0.0
        scene._picture_height_scale = height / peak if peak > 0 and math.isfinite(peak) else 1.0
    return scene._picture_height_scale


def graph(values: np.ndarray, scale: float) -> Picture:
    """Scalars as a polyline: point ``i`` at ``(i / (n-1), scale v_i, 0)``."""
    n = len(values)
    x = np.arange(n) / max(n - 1, 1)
    return Picture(np.stack([x, scale * values, np.zeros(n)], axis=1), lines=polyline(n))


# ---------------------------------------------------------------------- checks


def require_pillow() -> Any:
    """The ``PIL.Image`` module, or a ``SceneError`` naming the extra to install."""
    try:
        from PIL import Image
    except ImportError:
        raise SceneError(
            "--render needs Pillow: pip install 'kdsl[scenes]' (or pip install Pillow)"
        ) from None
    return Image


def check_outputs(render: str | None, usd: str | None, frames: int) -> None:
    """Refuse bad ``--render``/``--usd``/``--frames`` before any work (exit status 2)."""
    if frames < 1:
        raise SceneError(f"--frames must be >= 1, not {frames}")
    for path, suffixes, flag in ((render, tuple(IMAGE_SUFFIXES), "--render"),
                                 (usd, USD_SUFFIXES, "--usd")):  # fmt: skip
        if path is None:
            continue
        target = Path(path)
        if target.suffix.lower() not in suffixes:
            raise SceneError(f"{flag} writes {', '.join(suffixes)} files, not {path!r}")
        if not target.parent.is_dir():
            raise SceneError(f"cannot write {path}: no directory {target.parent}")
    if render is not None:
        require_pillow()
    if usd is not None:
        try:
            import pxr  # noqa: F401
        except ImportError:
            raise SceneError(
                "--usd needs usd-core: pip install 'kdsl[usd]' (or pip install usd-core)"
            ) from None


# ---------------------------------------------------------------------- frames


def record(scene: Any, dt: float, steps: int, frames: int) -> list[tuple[float, Picture]]:
    """Rerun ``scene`` from its start, keeping ``frames`` pictures spread over ``steps``.

    The first picture is the initial state when ``frames > 1``; the last is always the
    end of the run.
    """
    scene.reset()
    marks = sorted({round(k * steps / max(frames - 1, 1)) for k in range(frames)}) if frames > 1 \
        else [steps]  # fmt: skip
    out: list[tuple[float, Picture]] = []
    done = 0
    for mark in marks:
        while done < mark:
            scene.step(dt)
            done += 1
        x, _ = scene.state()
        out.append((scene.t, scene.picture(x)))
    return out


# ---------------------------------------------------------------------- drawing


@dataclass
class Camera:
    """An orthographic camera: a view rotation, then a uniform fit into the image."""

    rotation: np.ndarray  #: rows: the image's right, up and towards-the-viewer axes
    center: np.ndarray
    scale: float  #: pixels per scene unit
    size: tuple[int, int]

    @classmethod
    def fit(cls, pictures: list[Picture], size: tuple[int, int], yaw: float = 35.0,
            pitch: float = 25.0, margin: float = 0.08) -> Camera:  # fmt: skip
        """A camera that shows every point and sphere of ``pictures``, looking down by ``pitch``."""
        a, b = math.radians(yaw), math.radians(pitch)
        turn = np.array([[math.cos(a), 0.0, -math.sin(a)], [0.0, 1.0, 0.0],
                         [math.sin(a), 0.0, math.cos(a)]])  # fmt: skip
        tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(b), -math.sin(b)],
                         [0.0, math.sin(b), math.cos(b)]])  # fmt: skip
        rot = tilt @ turn
        seen = [p.points for p in pictures if len(p.points)]
        for p in pictures:
            for c, r in p.spheres:
                seen.append(np.asarray(c) + r * np.array([[-1, -1, -1], [1, 1, 1]]))
        allp = np.concatenate(seen) if seen else np.zeros((1, 3))
        allp = allp[np.all(np.isfinite(allp), axis=1)]
        if len(allp) == 0:
            allp = np.zeros((1, 3))
        view = allp @ rot.T
        lo, hi = view.min(axis=0), view.max(axis=0)
        extent = np.maximum(hi - lo, 1e-12)
        w, h = size
        scale = min(w * (1 - 2 * margin) / extent[0], h * (1 - 2 * margin) / extent[1])
        if not np.isfinite(scale) or extent.max() <= 1e-12:
            scale = 1.0
        center = rot.T @ ((lo + hi) / 2)
        return cls(rot, center, float(scale), size)

    def project(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (n, 2) and depth (n,; larger is nearer) of scene points."""
        v = (np.asarray(pts, dtype=np.float64) - self.center) @ self.rotation.T
        w, h = self.size
        xy = np.stack([w / 2 + self.scale * v[:, 0], h / 2 - self.scale * v[:, 1]], axis=1)
        return xy, v[:, 2]


def colormap(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Blue (low) through white to red (high), as (n, 3) floats in [0, 1]."""
    t = np.clip((values - lo) / (hi - lo), 0.0, 1.0) if hi > lo else np.full(len(values), 0.5)
    blue, white, red = (
        np.array([0.2, 0.35, 0.8]),
        np.array([0.95, 0.95, 0.95]),
        np.array([0.8, 0.2, 0.15]),
    )
    s = np.clip(2 * t, 0, 1)[:, None]
    u = np.clip(2 * t - 1, 0, 1)[:, None]
    return np.where(t[:, None] < 0.5, blue + (white - blue) * s, white + (red - white) * u)


def _rgb(c: np.ndarray) -> tuple[int, int, int]:
    r, g, b = (np.clip(c, 0, 1) * 255).astype(int)
    return int(r), int(g), int(b)


def draw(picture: Picture, camera: Camera, value_range: tuple[float, float] | None) -> Any:
    """One frame as a ``PIL.Image`` (RGB)."""
    Image = require_pillow()
    from PIL import ImageDraw

    img = Image.new("RGB", camera.size, BACKGROUND)
    pen = ImageDraw.Draw(img)
    pts = picture.points
    xy, depth = camera.project(pts) if len(pts) else (np.zeros((0, 2)), np.zeros(0))
    ok = np.all(np.isfinite(xy), axis=1)
    cols = (colormap(picture.values, *value_range) if picture.values is not None and value_range
            else None)  # fmt: skip
    # Painter's order over every primitive: (depth, kind, payload).
    items: list[tuple[float, int, Any]] = []
    for c, r in picture.spheres:
        cxy, cd = camera.project(np.asarray(c, dtype=np.float64)[None])
        items.append((float(cd[0]), 0, (cxy[0], r * camera.scale)))
    if picture.triangles is not None and len(picture.triangles):
        tri = picture.triangles[ok[picture.triangles].all(axis=1)]
        p = pts[tri]
        normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        norm = np.linalg.norm(normal, axis=1)
        shade = 0.35 + 0.65 * np.abs(normal @ LIGHT) / np.where(norm > 0, norm, 1.0)
        base = cols[tri].mean(axis=1) if cols is not None else np.tile(SURFACE_COLOR, (len(tri), 1))
        for k, t in enumerate(tri):
            items.append((float(depth[t].mean()), 1, (xy[t], base[k] * shade[k])))
    if picture.lines is not None:
        for a, b in picture.lines:
            if ok[a] and ok[b]:
                items.append((float(max(depth[a], depth[b])), 2, (xy[[a, b]], LINE_COLOR)))
    if picture.show_points:
        radius = max(2.0, min(6.0, 0.6 * min(camera.size) / math.sqrt(max(len(pts), 1)) / 4))
        for i in np.flatnonzero(ok):
            c = cols[i] if cols is not None else POINT_COLOR
            items.append((float(depth[i]), 3, (xy[i], radius, c)))
    items.sort(key=lambda it: (it[0], it[1]))
    for _, kind, data in items:
        if kind == 0:
            (cx, cy), r = data
            pen.ellipse([cx - r, cy - r, cx + r, cy + r], fill=_rgb(SPHERE_COLOR),
                        outline=_rgb(SPHERE_COLOR * 0.7))  # fmt: skip
        elif kind == 1:
            corners, c = data
            pen.polygon([tuple(q) for q in corners], fill=_rgb(c))
        elif kind == 2:
            ends, c = data
            pen.line([tuple(q) for q in ends], fill=_rgb(c), width=2)
        else:
            (cx, cy), r, c = data
            pen.ellipse([cx - r, cy - r, cx + r, cy + r], fill=_rgb(c), outline=_rgb(c * 0.6))
    return img


def _value_range(pictures: list[Picture]) -> tuple[float, float] | None:
    vals = [p.values[np.isfinite(p.values)] for p in pictures if p.values is not None]
    vals = [v for v in vals if len(v)]
    if not vals:
        return None
    return float(min(v.min() for v in vals)), float(max(v.max() for v in vals))


def _atomic(path: str, write: Callable[[str], None]) -> None:
    """Call ``write(tmp)`` for a temporary file beside ``path`` (same suffix), then rename."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_image(path: str, frames: list[tuple[float, Picture]], size: tuple[int, int] = (480, 360),
                fps: float = 20.0) -> None:  # fmt: skip
    """Draw ``frames`` to a GIF (every frame) or a PNG (the last one) at ``path``."""
    pictures = [p for _, p in frames]
    camera = Camera.fit(pictures, size)
    vr = _value_range(pictures)
    if Path(path).suffix.lower() == ".png":
        image = draw(pictures[-1], camera, vr)
        _atomic(path, lambda tmp: image.save(tmp, format="PNG"))
        return
    images = [draw(p, camera, vr) for p in pictures]
    duration = max(20, round(1000 / fps))
    _atomic(path, lambda tmp: images[0].save(tmp, format="GIF", save_all=True,
                                             append_images=images[1:], duration=duration,
                                             loop=0))  # fmt: skip


def write_usd(path: str, frames: list[tuple[float, Picture]], fps: float = 20.0) -> None:
    """Write ``frames`` as a USD animation through ``kdsl.render.UsdRenderer``."""
    from kdsl.render import UsdRenderer

    pictures = [p for _, p in frames]
    vr = _value_range(pictures)
    finite = [p.points[np.all(np.isfinite(p.points), axis=1)] for p in pictures]
    finite = [f for f in finite if len(f)]
    extent = float(np.ptp(np.concatenate(finite), axis=0).max()) if finite else 1.0
    size = 0.01 * (extent if extent > 0 else 1.0)  # point radius; lines at a third of it

    def write(tmp: str) -> None:
        os.unlink(tmp)  # usd-core creates the layer itself
        r = UsdRenderer(tmp, up_axis="Y", fps=fps)
        for i, p in enumerate(pictures):
            r.begin_frame(i / fps)
            cols = colormap(p.values, *vr) if p.values is not None and vr else None
            if p.triangles is not None and len(p.triangles):
                r.render_mesh("surface", p.points, p.triangles,
                              colors=cols if cols is not None else SURFACE_COLOR,
                              update_topology=True)  # fmt: skip
            if p.show_points and len(p.points):
                r.render_points("points", p.points, radius=size,
                                colors=cols if cols is not None else POINT_COLOR)  # fmt: skip
            if p.lines is not None and len(p.lines):
                r.render_line_list("lines", p.points, p.lines, color=LINE_COLOR, radius=size / 3)
            for k, (c, rad) in enumerate(p.spheres):
                r.render_sphere(f"sphere_{k}", c, (0.0, 0.0, 0.0, 1.0), rad, color=SPHERE_COLOR)
            r.end_frame()
        r.save()

    _atomic(path, write)
