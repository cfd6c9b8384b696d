"""docs/builtins.md is generated from the builtins and the stdlib, and must match them."""

import subprocess
import sys
from pathlib import Path

from kdsl.tools import builtins_doc

ROOT = Path(__file__).resolve().parents[2]


def test_builtins_doc_up_to_date():
    # A fresh process, so builtins or functions other tests define cannot leak in.
    proc = subprocess.run([sys.executable, "-m", "kdsl.tools.builtins_doc", "--check"],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr


def test_every_builtin_and_library_function_is_listed():
    text = (ROOT / "docs" / "builtins.md").read_text()
    names = [*builtins_doc.all_builtins(), *builtins_doc.stdlib_functions()]
    missing = [n for n in names if f"| `{n}` |" not in text]
    assert not missing, f"run python -m kdsl.tools.builtins_doc; missing: {missing}"
    assert "print" in names and "atomic_cas" in names and "printf" in names


def test_implementation_column_names_ops_and_library_code():
    from kdsl.frontend.builtins import BUILTINS

    assert builtins_doc.implementation(BUILTINS["sin"]) == "`math.sin`"
    assert "`kd.atomic_cas`" in builtins_doc.implementation(BUILTINS["atomic_cas"])
    assert "library code" in builtins_doc.implementation(BUILTINS["determinant"])


def test_doc_group_decorator_moves_a_function(monkeypatch):
    from kdsl.stdlib import doc_group

    name, (group, _, fn) = next(iter(builtins_doc.stdlib_functions().items()))
    monkeypatch.setattr(fn, "__kdsl_group__", group, raising=False)  # restored after the test
    assert doc_group("elsewhere")(fn) is fn
    assert builtins_doc.stdlib_functions()[name][0] == "elsewhere"
    assert "### elsewhere\n" in builtins_doc.render()
