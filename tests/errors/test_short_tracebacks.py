"""Short tracebacks (issue 13): a kdsl error raised from a user call shows the user's
frames and kdsl's located message, without kdsl-internal frames, unless
``KDSL_TRACEBACK=full``. Modelled on JAX's traceback filtering."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import traceback
from pathlib import Path

import numpy as np
import pytest

import kdsl as wp
from kdsl.errors import (
    HIDDEN_FRAMES_NOTE,
    KdslError,
    KdslLaunchError,
    KdslTypeError,
    api_boundary,
    is_internal_frame,
)

SCRIPT = textwrap.dedent("""\
    import kdsl as wp


    @wp.kernel
    def k(a: wp.array(dtype=float), b: wp.array(dtype=wp.float64)):
        i = wp.tid()
        a[i] = a[i] + b[i]


    def main():
        a = wp.zeros(4, dtype=float)
        b = wp.zeros(4, dtype=wp.float64)
        wp.launch(k, dim=4, inputs=[a, b])


    main()
""")

#: Traceback header, two user frames of two lines each, the message with its
#: location (three lines), the compile context and the note: 11 lines. Allow a little.
MAX_LINES = 13


def _run_script(tmp_path: Path, full: bool) -> subprocess.CompletedProcess:
    path = tmp_path / "sim.py"
    path.write_text(SCRIPT)
    env = {k: v for k, v in os.environ.items() if k != "KDSL_TRACEBACK"}
    if full:
        env["KDSL_TRACEBACK"] = "full"
    return subprocess.run([sys.executable, str(path)], capture_output=True, text=True,
                          env=env, timeout=120)  # fmt: skip


def test_type_error_in_launched_kernel_has_a_short_traceback(tmp_path):
    proc = _run_script(tmp_path, full=False)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 1
    assert len(err) <= MAX_LINES, proc.stderr
    text = proc.stderr
    assert 'sim.py", line 16, in <module>' in text and 'sim.py", line 13, in main' in text
    assert "KdslTypeError: cannot add f32 and f64" in text
    assert 'sim.py", line 7, column 12, in k:' in text and "a[i] + b[i]" in text
    assert "kdsl" + os.sep not in text.replace("kdsl.errors", "")  # no kdsl file paths
    assert err[-1] == HIDDEN_FRAMES_NOTE


def test_full_traceback_on_request(tmp_path):
    proc = _run_script(tmp_path, full=True)
    assert os.path.join("kdsl", "runtime", "launch.py") in proc.stderr
    assert HIDDEN_FRAMES_NOTE not in proc.stderr
    assert len(proc.stderr.splitlines()) > MAX_LINES


def _frames(e: BaseException) -> list[str]:
    return [f.filename for f in traceback.extract_tb(e.__traceback__)]


@wp.kernel
def _needs_two(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    i = wp.tid()
    b[i] = a[i]


def test_launch_error_keeps_only_user_frames(monkeypatch):
    monkeypatch.delenv("KDSL_TRACEBACK", raising=False)
    with pytest.raises(KdslLaunchError) as info:
        wp.launch(_needs_two, 3, [wp.zeros(3, dtype=float)])
    assert _frames(info.value) == [__file__]
    assert f'File "{__file__}"' in str(info.value)  # located at this launch


@wp.kernel
def _replays_atomic(x: wp.array(dtype=float), y: wp.array(dtype=float), c: wp.array(dtype=int)):
    i = wp.tid()
    slot = wp.atomic_add(c, 0, 1)
    y[slot] = x[i]


def test_tape_backward_error_keeps_only_user_frames(monkeypatch):
    monkeypatch.delenv("KDSL_TRACEBACK", raising=False)
    x = wp.array(np.ones(4, np.float32), dtype=float, requires_grad=True)
    y = wp.zeros(4, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(_replays_atomic, 4, [x], [y, wp.zeros(1, dtype=int)])
    with pytest.raises(KdslError, match="cannot replay") as info:
        tape.backward(grads={y: wp.ones(4, dtype=float)})
    assert _frames(info.value) == [__file__]
    assert info.value.__notes__ == [HIDDEN_FRAMES_NOTE]


def test_boundary_leaves_other_exceptions_alone():
    @api_boundary
    def buggy():
        return {}["missing"]

    with pytest.raises(KeyError) as info:
        buggy()
    assert any(is_internal_frame(f) for f in _frames(info.value))  # errors.py's wrapper


def test_nested_boundaries_note_once(monkeypatch):
    monkeypatch.delenv("KDSL_TRACEBACK", raising=False)

    @api_boundary
    def inner():
        raise KdslTypeError("bad")

    @api_boundary
    def outer():
        inner()

    with pytest.raises(KdslTypeError) as info:
        outer()
    assert info.value.__notes__ == [HIDDEN_FRAMES_NOTE]


def test_full_setting_read_at_each_error(monkeypatch):
    monkeypatch.setenv("KDSL_TRACEBACK", "full")
    with pytest.raises(KdslLaunchError) as info:
        wp.launch(_needs_two, 3, [wp.zeros(3, dtype=float)])
    assert any(is_internal_frame(f) for f in _frames(info.value))
    assert not getattr(info.value, "__notes__", None)
