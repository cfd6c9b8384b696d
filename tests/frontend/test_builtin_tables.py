"""Builtins come from explicit group tables, merged by ``kdsl.frontend.builtins`` alone."""

import ast
from pathlib import Path

import pytest

from kdsl.frontend import builtins
from kdsl.frontend.builtins_base import Builtin, BuiltinTable

FRONTEND = Path(builtins.__file__).parent


def _lower(em, args, node):
    return None


def test_builtins_are_the_union_of_the_group_tables():
    names = [name for table in builtins.TABLES for name in table.builtins]
    assert sorted(names) == sorted(builtins.BUILTINS)
    for table in builtins.TABLES:
        for name, b in table.builtins.items():
            assert builtins.BUILTINS[name] is b
        for python, b in table.aliases.items():
            assert builtins.PYTHON_ALIASES[python] is b


def test_no_group_module_imports_the_merge():
    # The groups import the shared definitions (builtins_base), never builtins.py: no cycle.
    for table in builtins.TABLES:
        path = FRONTEND / (table.source.rpartition(".")[2] + ".py")
        tree = ast.parse(path.read_text())
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert "kdsl.frontend.builtins" not in imported, path.name


def test_a_name_defined_by_two_tables_is_refused():
    a, b = BuiltinTable("group_a"), BuiltinTable("group_b")
    a.define("twice", (1, 1), "A.", "math")(_lower)
    b.define("twice", (1, 1), "B.", "math")(_lower)
    with pytest.raises(ValueError, match="'twice' is defined by both group_a and group_b"):
        builtins.merge_tables((a, b))


def test_a_python_alias_defined_by_two_tables_is_refused():
    a, b = BuiltinTable("group_a"), BuiltinTable("group_b")
    a.alias(abs, Builtin("x", _lower, "X.", (1, 1), "math"))
    b.alias(abs, Builtin("y", _lower, "Y.", (1, 1), "math"))
    with pytest.raises(ValueError, match=r"alias .* is defined by both group_a and group_b"):
        builtins.merge_tables((a, b))


def test_a_name_defined_twice_in_one_table_is_refused():
    table = BuiltinTable("group_a")
    table.define("twice", (1, 1), "A.", "math")(_lower)
    with pytest.raises(ValueError, match="'twice' is defined twice in group_a"):
        table.define("twice", (1, 1), "A.", "math")(_lower)


def test_a_builtin_keeps_its_doc_and_identity():
    b = builtins.BUILTINS["sin"]
    assert b.__doc__ == b.doc and b.group == "math"
    # Compared by identity, and hashable: the expression visitor looks builtins up by object.
    assert {b: 1}[b] == 1
    assert b != Builtin(b.name, b.lower, b.doc, b.arity, b.group, b.keywords)
    assert repr(b) == "<kdsl builtin sin>"
