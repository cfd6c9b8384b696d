"""``kdsl conformance`` fails, with the reason, when it tested nothing (issue 13).

A run whose backend has no device, whose cases were all skipped, or whose ``-k``
matched nothing used to print "0 passed" and exit 0, which reads as green.
"""

import pytest

from kdsl.backends.registry import get_backend
from kdsl.cli import main


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_conformance_on_a_backend_without_device_fails(capsys, monkeypatch):
    monkeypatch.setattr(type(get_backend("cuda")), "devices", lambda self: [])
    code, _out, err = _run(capsys, "conformance", "--backend", "cuda")
    assert code == 1
    assert "nothing was tested: the cuda backend has no device on this machine" in err


def test_conformance_where_no_case_matches_fails(capsys):
    code, _out, err = _run(capsys, "conformance", "--backend", "interp", "-k", "no_such_case_x")
    assert code == 1
    assert "nothing was tested: no case matches -k 'no_such_case_x'" in err


def test_conformance_where_every_case_is_skipped_fails(capsys, monkeypatch):
    interp = type(get_backend("interp"))
    monkeypatch.setattr(interp, "capabilities", interp.capabilities - {"fp64"})
    code, out, err = _run(capsys, "conformance", "--backend", "interp", "-k", "arith_add_f64")
    assert code == 1
    assert out.splitlines()[-1] == "0 passed, 0 failed, 1 skipped"
    assert "nothing was tested: all 1 selected cases were skipped" in err


def test_conformance_unknown_backend_is_a_usage_error(capsys):
    code, _, err = _run(capsys, "conformance", "--backend", "no-such-backend")
    assert code == 2 and "no-such-backend" in err


@pytest.mark.parametrize("k", ["tid_1d"])
def test_conformance_that_ran_a_case_passes(capsys, k):
    code, out, err = _run(capsys, "conformance", "--backend", "interp", "-k", k)
    assert code == 0 and out.splitlines()[-1] == "1 passed, 0 failed" and not err
