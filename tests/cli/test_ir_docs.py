"""docs/ir.md is generated from the op catalog and must match it."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_ir_docs_up_to_date():
    # A fresh process, so ops that other tests register cannot leak into the page.
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "gen_ir_docs.py"), "--check"],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr


def test_ir_docs_list_every_op():
    from kdsl.ir import CATALOG

    text = (ROOT / "docs" / "ir.md").read_text()
    missing = [op.name for op in CATALOG if f"### `{op.name}`" not in text]
    assert not missing
