"""No kdsl module keeps a private name while another module imports it.

A name that another module needs is part of its module's interface: it is public
(no leading underscore) and has a docstring. This test walks every module under
``kdsl/`` with ``ast`` and fails when an import, at module level or inside a function,

- takes a name with a single leading underscore from another kdsl module
  (``from kdsl.frontend.kernel import _symbol``), or
- names a kdsl module whose own name starts with an underscore
  (``import kdsl.passes._rewrite``, ``from kdsl.passes._adjoint import x``).

Left out: dunder names (``__version__``, ``__init__``), which are Python's protocol
rather than privacy; ``__future__`` and every non-kdsl module, whose privacy is their
own business; a module importing from itself. No facade needs an exception:
``kdsl/__init__.py`` re-exports public names only.

``KNOWN`` lists the imports that other work in progress still has to clear, each by
(importing module, imported module, name); an entry that no longer occurs fails the
test too, so the list only shrinks.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import kdsl

ROOT = Path(kdsl.__file__).parent

#: (importing module, imported module, name or None for the module itself): private
#: imports still to clear. Empty: every private name in use has been made public.
KNOWN: set[tuple[str, str, str | None]] = set()


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _module_name(path: Path) -> tuple[str, str]:
    """(the module's dotted name, the package its relative imports start from)."""
    rel = path.relative_to(ROOT.parent).with_suffix("")
    module = ".".join(rel.parts).removesuffix(".__init__")
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    return module, package


def _private_imports(path: Path) -> list[tuple[str, str, str | None, int]]:
    """(module, imported module, private name or None, line) of each private import."""
    module, package = _module_name(path)
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            targets = [(target, a.name) for a in node.names]
        else:
            continue
        for target, name in targets:
            if not (target == "kdsl" or target.startswith("kdsl.")) or target == module:
                continue
            if any(_private(part) for part in target.split(".")):
                found.append((module, target, None, node.lineno))
            elif name is not None and _private(name):
                found.append((module, target, name, node.lineno))
    return found


def test_no_module_imports_a_private_name():
    found = [hit for path in sorted(ROOT.rglob("*.py")) for hit in _private_imports(path)]
    new = [
        f"{mod}:{line} imports {target}" + (f".{name}" if name else " (a private module)")
        for mod, target, name, line in found
        if (mod, target, name) not in KNOWN
    ]
    assert not new, "make these names public (with a docstring):\n" + "\n".join(new)
    gone = KNOWN - {(mod, target, name) for mod, target, name, _ in found}
    assert not gone, f"cleared; remove from KNOWN: {sorted(gone, key=str)}"


def test_the_check_sees_private_imports(tmp_path, monkeypatch):
    # A module of a throwaway package named kdsl, so the walk above has something to find.
    pkg = tmp_path / "kdsl" / "sub"
    pkg.mkdir(parents=True)
    (pkg / "a.py").write_text(
        "from kdsl.sub.b import _hidden, public, __version__\n"
        "from . import _c\n"
        "def f():\n"
        "    import kdsl.sub._d\n"
        "    from __future__ import annotations\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path / "kdsl")
    hits = {(t, n) for _, t, n, _ in _private_imports(pkg / "a.py")}
    assert hits == {("kdsl.sub.b", "_hidden"), ("kdsl.sub", "_c"), ("kdsl.sub._d", None)}
