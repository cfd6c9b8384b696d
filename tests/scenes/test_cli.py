"""``kdsl scene``: outputs, and bad input (exit status 2, choices listed, no half JSON)."""

import json

import pytest

from kdsl.cli import main


def _run(capsys, *argv):
    code = main(["scene", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_list_names_every_scene(capsys):
    code, out, _ = _run(capsys, "list")
    assert code == 0
    for name in ("particles", "chain", "heat", "wave", "nbody", "cloth", "stiff_odes", "ocean",
                 "throw"):  # fmt: skip
        assert name in out


def test_run_prints_times_and_error_and_writes_json(capsys, tmp_path):
    out_json = tmp_path / "r.json"
    code, out, _ = _run(capsys, "run", "chain", "--param", "count=4", "--steps", "20",
                        "--integrator", "rk4", "--json", str(out_json))  # fmt: skip
    assert code == 0
    assert "us/step" in out and "compile" in out and "error" in out
    data = json.loads(out_json.read_text())
    assert data["steps"] == 20 and data["integrator"] == "rk4" and data["error"] < 1e-3
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_stability_and_info_run(capsys):
    code, out, _ = _run(capsys, "stability", "chain", "--param", "count=1", "--integrator",
                        "symplectic_euler", "--precision", "f32", "--horizon", "200",
                        "--drift-steps", "100", "--dt", "0.01")  # fmt: skip
    assert code == 0 and "symplectic_euler" in out and "0.141" in out
    code, out, _ = _run(capsys, "info", "heat", "--param", "grid=4")
    assert code == 0 and "laplacian" in out and "total" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "nope"], "unknown scene 'nope' (choices: particles, chain, heat, wave"),
        (["run", "heat", "--integrator", "velocity_verlet"], "choices: explicit_euler, rk4"),
        (["run", "chain", "--precision", "f8"], "choices: f16, f32, f64"),
        (["run", "chain", "--dt", "0"], "dt must be a finite number > 0"),
        (["run", "chain", "--dt", "nan"], "dt must be a finite number > 0"),
        (["run", "chain", "--dt", "-1"], "dt must be a finite number > 0"),
        (["run", "chain", "--backend", "tpu"], "choices: cpu, interp, cuda"),
        (["run", "chain", "--param", "mass=2"], "no parameter 'mass'"),
        (["stability", "chain", "--precision", "f32,f7"], "choices: f16, f32, f64"),
        (["info", "chain", "--integrator", "leapfrog"], "choices: explicit_euler"),
    ],
)
def test_bad_input_exits_2_with_the_choices_and_writes_nothing(capsys, tmp_path, argv, message):
    out_json = tmp_path / "out.json"
    code, _, err = _run(capsys, *argv, "--json", str(out_json))
    assert code == 2
    assert message in err
    assert list(tmp_path.iterdir()) == []


def test_unavailable_cuda_is_a_clear_error(capsys):
    import kdsl

    if kdsl.is_cuda_available():
        pytest.skip("cuda is available here")
    code, _, err = _run(capsys, "run", "chain", "--backend", "cuda")
    assert code == 2 and "'cuda' is not available here (available: cpu, interp)" in err


def test_json_is_not_left_half_written(tmp_path, monkeypatch):
    from kdsl.scenes.cli import write_json

    target = tmp_path / "x.json"
    with pytest.raises(TypeError):
        write_json(str(target), {"a": 1, "bad": object.__new__(_Unserializable)})
    assert list(tmp_path.iterdir()) == []


class _Unserializable:
    def __float__(self):
        raise TypeError("not a number")


def test_bad_param_syntax_and_missing_json_directory(capsys, tmp_path):
    code, _, err = _run(capsys, "run", "chain", "--param", "count")
    assert code == 2 and "--param takes NAME=VALUE" in err
    code, _, err = _run(capsys, "run", "chain", "--param", "count=many")
    assert code == 2 and "is not a number" in err
    code, _, err = _run(capsys, "run", "chain", "--steps", "2", "--param", "count=2",
                        "--json", str(tmp_path / "no" / "r.json"))  # fmt: skip
    assert code == 2 and "no directory" in err


def test_precision_the_backend_lacks_is_refused(monkeypatch):
    from kdsl.backends.registry import get_backend
    from kdsl.scenes import SceneError
    from kdsl.scenes.measure import make_scene

    backend = get_backend("interp")
    monkeypatch.setattr(type(backend), "capabilities", frozenset({"fp32", "fp64"}))
    with pytest.raises(
        SceneError, match=r"backend 'interp' has no f16 \(it has: \['fp32', 'fp64'\]\)"
    ):
        make_scene("chain", "f16", backend="interp", count=2)


def test_unknown_binding_is_refused():
    from kdsl.scenes import SceneError, bind

    with pytest.raises(SceneError, match="choices: kdsl, warp"):
        bind("jax")
