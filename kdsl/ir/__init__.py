"""kdsl's intermediate representation: types, ops, the op catalog, text form.

Import from here, not from the submodules::

    from kdsl.ir import Builder, CATALOG, Module, parse_module, print_module, types
"""

from kdsl.ir import (
    ops_arith,
    ops_debug,
    ops_func,
    ops_local,
    ops_math,
    ops_mem,
    ops_pointer,
    ops_prefetch,
    ops_print,
    ops_scf,
    ops_target,
    ops_vec,
    records,
    types,
)
from kdsl.ir.builder import Builder, create_op, new_func
from kdsl.ir.catalog import CATALOG, OpDef, OpRegistry
from kdsl.ir.core import (
    UNKNOWN_LOC,
    Block,
    BlockArgument,
    Loc,
    Module,
    Operation,
    OpResult,
    Region,
    Value,
)
from kdsl.ir.parser import parse_module
from kdsl.ir.printer import print_module, print_op
from kdsl.ir.verifier import verify_module

__all__ = [
    "CATALOG", "UNKNOWN_LOC", "Block", "BlockArgument", "Builder", "Loc", "Module", "OpDef",
    "OpRegistry", "OpResult", "Operation", "Region", "Value", "create_op", "new_func",
    "parse_module", "print_module", "print_op", "types", "verify_module",
]  # fmt: skip
