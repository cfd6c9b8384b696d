"""``kdsl scene sweep`` and ``kdsl scene extremes``: outputs whole or not at all, the --yes guard."""

import builtins
import json

import pytest

from kdsl.cli import main

#: A sweep of a few milliseconds: one spring, two integrators, two dts.
SMALL = ["chain", "--param", "count=1", "--integrator", "rk4,symplectic_euler",
         "--precision", "f64", "--dts", "2", "--t-end", "0.05"]  # fmt: skip


def _run(capsys, *argv):
    code = main(["scene", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_sweep_prints_a_table_and_writes_whole_json(capsys, tmp_path):
    out_json = tmp_path / "s.json"
    code, out, _ = _run(capsys, "sweep", *SMALL, "--json", str(out_json))
    assert code == 0 and "estimated" in out and "us/step" in out
    data = json.loads(out_json.read_text())
    runs = data["runs"]
    assert len(runs) == 4 and data["dts"] == [1e-3, 5e-4]
    assert {r["integrator"] for r in runs} == {"rk4", "symplectic_euler"}
    assert all(r["t_end"] == pytest.approx(0.05) for r in runs)
    rk4 = sorted((r for r in runs if r["integrator"] == "rk4"), key=lambda r: r["dt"])
    assert rk4[0]["error"] < rk4[1]["error"]  # smaller dt, smaller error
    assert [p.name for p in tmp_path.iterdir()] == ["s.json"]


def test_sweep_plot_is_written_as_a_png(capsys, tmp_path):
    pytest.importorskip("matplotlib")
    plot = tmp_path / "s.png"
    code, _, _ = _run(capsys, "sweep", *SMALL, "--plot", str(plot))
    assert code == 0
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["s.png"]


def test_sweep_above_the_threshold_needs_yes(capsys, tmp_path):
    out_json = tmp_path / "s.json"
    code, out, err = _run(capsys, "sweep", *SMALL, "--max-seconds", "0", "--json", str(out_json))
    assert code == 2 and "estimated" in out
    assert "pass --yes to run it" in err and "would take about" in err
    assert list(tmp_path.iterdir()) == []
    code, _, _ = _run(capsys, "sweep", *SMALL, "--max-seconds", "0", "--yes", "--json",
                      str(out_json))  # fmt: skip
    assert code == 0 and out_json.exists()


def test_sweep_without_matplotlib_names_the_extra(capsys, tmp_path, monkeypatch):
    real_import = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name.startswith("matplotlib"):
            raise ImportError("No module named 'matplotlib'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    code, out, err = _run(capsys, "sweep", *SMALL, "--plot", str(tmp_path / "s.png"))
    assert code == 2 and "kdsl[scenes]" in err and "matplotlib" in err
    assert out == "" and list(tmp_path.iterdir()) == []  # refused before any work


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["sweep", "nope"], "unknown scene 'nope'"),
        (["sweep", "heat", "--integrator", "rk4,leapfrog"], "choices: explicit_euler, rk4"),
        (["sweep", "heat", "--precision", "f32,f8"], "choices: f16, f32, f64"),
        (["sweep", "heat", "--dt", "1e-4,0"], "dt must be a finite number > 0"),
        (["sweep", "heat", "--t-end", "nan"], "must be a finite number > 0"),
        (["sweep", "heat", "--dts", "0"], "--dts must be >= 1"),
        (["sweep", "heat", "--dt", ","], "--dt lists no time step"),
        (["sweep", "heat", "--backend", "cpu,tpu"], "choices: cpu, interp, cuda"),
        (["extremes", "heat", "--precision", "f9"], "choices: f16, f32, f64"),
        (["extremes", "nope"], "unknown scene 'nope'"),
    ],
)
def test_sweep_and_extremes_bad_input(capsys, tmp_path, argv, message):
    code, _, err = _run(capsys, *argv, "--json", str(tmp_path / "x.json"))
    assert code == 2 and message in err
    assert list(tmp_path.iterdir()) == []


def test_sweep_into_a_missing_directory_is_refused_before_running(capsys, tmp_path):
    code, out, err = _run(capsys, "sweep", *SMALL, "--json", str(tmp_path / "no" / "s.json"))
    assert code == 2 and "no directory" in err and out == ""


def test_extremes_report_errors_and_name_the_blowup(capsys, monkeypatch):
    from kdsl.scenes import extremes

    cases = [extremes.Case("stiffness stiffness=1e+04", {"count": 1, "stiffness": 1e4},
                           "symplectic_euler", 0.05, 50),
             extremes.Case("stiffness stiffness=1", {"count": 1, "stiffness": 1.0},
                           "symplectic_euler", 0.05, 50)]  # fmt: skip
    monkeypatch.setitem(extremes.EXTREMES, "chain", cases)
    code, out, _ = _run(capsys, "extremes", "chain", "--precision", "f32")
    assert code == 0
    blown, calm = out.splitlines()[2:4]
    assert "step " in blown and ("NaN" in blown or "Inf" in blown) and "kernel" in blown
    assert "nan" not in calm.lower() and "e-0" in calm


def test_every_scene_has_extreme_cases():
    from kdsl.scenes import scene_class, scene_names
    from kdsl.scenes.extremes import EXTREMES

    assert set(EXTREMES) == set(scene_names())
    for name, cases in EXTREMES.items():
        cls = scene_class(name)
        for case in cases:
            assert case.integrator in cls.integrators and set(case.params) <= set(cls.defaults)
