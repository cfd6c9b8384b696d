"""``kdsl ir --features``: the feature analysis of a kernel, its optimized IR or its adjoint."""

import textwrap
from pathlib import Path

from kdsl.cli import main

KERNEL = textwrap.dedent("""\
    import kdsl as wp

    @wp.kernel
    def looped(x: wp.array(dtype=float), n: int):
        i = wp.tid()
        s = float(0.0)
        for _ in range(n):
            s = wp.sin(s + x[i])
        x[i] = s
    """)


def _names(out: str) -> set[str]:
    line = next(ln for ln in out.splitlines() if ln.startswith("names: "))
    return set(line[len("names: ") :].split(", "))


def test_features_of_a_kernel_and_of_its_adjoint(tmp_path: Path, capsys):
    path = tmp_path / "looped.py"
    path.write_text(KERNEL)
    assert main(["ir", f"{path}:looped", "--features"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("ops: ") and {"loops", "math.sin"} <= _names(out)
    assert "adjoint" not in _names(out)
    assert main(["ir", f"{path}:looped", "--stage", "adjoint", "--features"]) == 0
    out = capsys.readouterr().out
    assert {"adjoint", "tapes", "math.cos"} <= _names(out)
