"""kdsl's subpackages import one way (docs/decisions.md, "Layers").

Every import counts, module-level and inside functions alike; only imports under
``if TYPE_CHECKING:`` are left out (they never run). The public facade
(``kdsl/__init__.py``, ``__main__``, the CLI) and the packages that drive everything
(``testing``, ``tools``) may import any layer; nothing imports them back.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import kdsl

ROOT = Path(kdsl.__file__).parent

#: The layers, lowest first. A unit may import units of its own or a lower rank only.
LAYERS: list[set[str]] = [
    {"errors", "config"},
    {"ir"},
    {"passes", "types"},
    {"frontend", "backends"},
    {"stdlib", "ext"},
    {"compiler"},
    {"runtime"},
    {"interop", "autograd", "utils", "optim", "render", "texture"},
    {"geometry"},
    {"jax_experimental"},
    {"scenes"},  # user code on the public API, above everything (docs/scenes.md)
]
FACADES = {"__init__", "__main__", "cli", "testing", "tools", "examples"}
#: Upward imports allowed, with the reason. The standard library is kernel code written
#: against the public API (``wp.sin``, ``wp.vec3``), as user code is: the frontend
#: resolves those names when it compiles a body, and ``kdsl/__init__.py`` imports the
#: standard library last, so ``import kdsl as wp`` there sees every name it needs.
#: Scenes are user code on the public API (``import kdsl``), like the standard library.
ALLOWED = {("stdlib", "__init__"), ("scenes", "__init__")}
RANK = {unit: rank for rank, units in enumerate(LAYERS) for unit in units}


def _unit(module: str) -> str:
    parts = module.split(".")
    if module == "kdsl":
        return "__init__"
    return parts[1] if len(parts) > 1 else "__init__"


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                lines.update(range(sub.lineno, (sub.end_lineno or sub.lineno) + 1))
    return lines


def _imports(path: Path) -> list[tuple[str, int]]:
    """(imported kdsl module, line) of every import in ``path`` that can run."""
    rel = path.relative_to(ROOT.parent).with_suffix("")
    module = ".".join(rel.parts).removesuffix(".__init__")
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text())
    skip = _type_checking_lines(tree)
    out = []
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target == "kdsl":  # ``from kdsl import config``: the submodules named
                out += [(_submodule(a.name), node.lineno) for a in node.names]
            else:
                out.append((target, node.lineno))
    return [(m, line) for m, line in out if m == "kdsl" or m.startswith("kdsl.")]


def _submodule(name: str) -> str:
    is_module = (ROOT / f"{name}.py").exists() or (ROOT / name / "__init__.py").exists()
    return f"kdsl.{name}" if is_module else "kdsl"


def _edges() -> dict[tuple[str, str], list[str]]:
    """(importing unit, imported unit) -> the places that import that way."""
    edges: dict[tuple[str, str], list[str]] = defaultdict(list)
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        src = _unit(".".join(rel.parts))
        for target, line in _imports(path):
            dst = _unit(target)
            if dst != src:
                edges[(src, dst)].append(f"{path.relative_to(ROOT.parent)}:{line} {target}")
    return edges


def _cycles(edges: dict[tuple[str, str], list[str]]) -> list[set[str]]:
    """Strongly connected components of more than one unit (Tarjan)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for src, dst in edges:
        graph[src].add(dst)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_between_subpackages():
    # The facades import every layer by design; cycles through them are not layering.
    edges = {k: v for k, v in _edges().items() if not set(k) & FACADES}
    cycles = _cycles(edges)
    detail = [
        f"{a} -> {b}: {edges[(a, b)][0]}"
        for comp in cycles
        for a, b in edges
        if a in comp and b in comp
    ]
    assert not cycles, "import cycles between subpackages:\n" + "\n".join(detail)


def test_every_import_goes_down_the_layers():
    units = {_unit(".".join(p.relative_to(ROOT.parent).with_suffix("").parts))
             for p in ROOT.rglob("*.py")}  # fmt: skip
    unknown = units - set(RANK) - FACADES
    assert not unknown, f"place these units in LAYERS: {sorted(unknown)}"
    upward = [
        f"{src} (layer {RANK[src]}) imports {dst} (layer {RANK.get(dst, 'facade')}): {where[0]}"
        for (src, dst), where in sorted(_edges().items())
        if src not in FACADES
        and (src, dst) not in ALLOWED
        and (dst in FACADES or RANK[dst] > RANK[src])
    ]
    assert not upward, "imports that go up the layers:\n" + "\n".join(upward)


def test_the_checker_sees_lazy_imports(tmp_path):
    """A function-level import counts like a module-level one."""
    f = tmp_path / "kdsl" / "runtime" / "x.py"
    f.parent.mkdir(parents=True)
    f.write_text("def f():\n    from kdsl.cli import main\n")
    global ROOT
    saved, ROOT = ROOT, tmp_path / "kdsl"
    try:
        assert _imports(f) == [("kdsl.cli", 2)]
    finally:
        ROOT = saved
