"""kdsl scene run --render (Pillow) and --usd (usd-core): frames, sizes, content, errors."""

import sys

import numpy as np
import pytest

from kdsl.cli import main
from kdsl.scenes import render

Image = pytest.importorskip("PIL.Image", reason="needs Pillow (the scenes extra)")


def _run(capsys, *args):
    status = main(["scene", "run", *args])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_gif_has_the_frames_and_is_not_blank(tmp_path, capsys):
    gif = tmp_path / "p.gif"
    status, out, err = _run(capsys, "particles", "--param", "count=16", "--steps", "20",
                            "--render", str(gif), "--frames", "5")  # fmt: skip
    assert status == 0, err
    assert f"picture    {gif}" in out
    im = Image.open(gif)
    assert (im.n_frames, im.size) == (5, (480, 360))
    first = np.asarray(im.convert("RGB"))
    im.seek(4)
    last = np.asarray(im.convert("RGB"))
    background = np.all(last == render.BACKGROUND, axis=2)
    assert 0 < (~background).sum() < background.size  # something drawn, not everything
    assert not np.array_equal(first, last)  # the particles moved


def test_png_of_a_surface_scene_and_its_usd_stage(tmp_path, capsys):
    pxr = pytest.importorskip("pxr", reason="needs usd-core (the usd extra)")
    png, usd = tmp_path / "heat.png", tmp_path / "heat.usda"
    status, _, err = _run(capsys, "heat", "--param", "grid=8", "--steps", "10",
                            "--render", str(png), "--usd", str(usd), "--frames", "3")  # fmt: skip
    assert status == 0, err
    im = Image.open(png).convert("RGB")
    assert im.size == (480, 360)
    pixels = np.asarray(im).reshape(-1, 3)
    assert len(np.unique(pixels, axis=0)) > 10  # shaded, colored triangles
    stage = pxr.Usd.Stage.Open(str(usd))
    surface = stage.GetPrimAtPath("/root/surface")
    assert surface.GetTypeName() == "Mesh"
    assert surface.GetAttribute("points").GetTimeSamples() == [0.0, 1.0, 2.0]
    assert len(surface.GetAttribute("points").Get(2.0)) == 64  # the 8 x 8 grid
    assert sorted(p.name for p in tmp_path.iterdir()) == ["heat.png", "heat.usda"]  # no temp


def test_bad_requests_exit_2_before_any_work(tmp_path, capsys, monkeypatch):
    for args, message in [
        (["--render", str(tmp_path / "x.jpg")], "--render writes .gif, .png files"),
        (["--render", str(tmp_path / "no" / "x.gif")], "no directory"),
        (["--usd", str(tmp_path / "x.obj")], "--usd writes .usd, .usda, .usdc"),
        (["--render", str(tmp_path / "x.gif"), "--frames", "0"], "--frames must be >= 1"),
    ]:
        status, out, err = _run(capsys, "particles", *args)
        assert status == 2 and message in err, (args, err)
        assert out == ""  # refused before the run
    monkeypatch.setitem(sys.modules, "PIL", None)
    status, _, err = _run(capsys, "particles", "--render", str(tmp_path / "x.gif"))
    assert status == 2 and "pip install 'kdsl[scenes]'" in err
    monkeypatch.setitem(sys.modules, "pxr", None)
    status, _, err = _run(capsys, "particles", "--usd", str(tmp_path / "x.usda"))
    assert status == 2 and "pip install 'kdsl[usd]'" in err
    assert list(tmp_path.iterdir()) == []


def test_default_picture_of_scalar_dofs_is_a_graph():
    from kdsl.scenes.measure import make_scene

    scene = make_scene("chain", "f32", None, "cpu", count=6)
    pic = scene.picture(scene.state()[0])
    assert pic.points.shape == (6, 3) and pic.lines.tolist() == [[i, i + 1] for i in range(5)]
    assert np.max(np.abs(pic.points[:, 1])) == pytest.approx(0.3)  # scaled to the start's peak
