"""Differential test: the standard pipeline never changes what a program computes.

Random programs over i32 and f32 scalars (arithmetic with constants, compares,
selects and scf.if) are evaluated with the catalog's interpreter rules before and
after the passes; results must agree bit for bit (NaN payloads aside).
"""

from __future__ import annotations

from collections import ChainMap

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from kdsl.ir import Block, Builder, Module, Region, new_func, types, verify_module
from kdsl.passes import DEFAULT_PIPELINE, run_pipeline


class _Ctx:
    def __init__(self, env: ChainMap) -> None:
        self.env = env

    def run_region(self, region, args):
        return run_block(region.block, args, self.env)


def run_block(block, args, outer: ChainMap | None = None):
    env = (outer or ChainMap()).new_child(dict(zip(block.args, args)))
    for op in block.ops:
        vals = [env[v] for v in op.operands]
        if op.opdef.is_terminator:
            return vals
        out = op.opdef.interp(_Ctx(env), op, *vals)
        outs = [out] if len(op.results) == 1 else list(out or ())
        env.update(zip(op.results, outs))
    raise AssertionError("block without terminator")


_BIN = ["arith.add", "arith.sub", "arith.mul", "arith.div", "arith.min", "arith.max"]
_CONSTS = {types.I32: [0, 1, -1, 7, 2**31 - 1], types.F32: [0.0, -0.0, 1.0, 2.5, float("inf")]}


def _build(draw, b: Builder, pool: dict, depth: int) -> None:
    for _ in range(draw(st.integers(1, 6))):
        t = draw(st.sampled_from([types.I32, types.F32]))
        kind = draw(st.sampled_from(["const", "bin", "bin", "cmp_select", "neg", "if"]))
        vals = pool[t]
        if kind == "const":
            vals.append(b.constant(draw(st.sampled_from(_CONSTS[t])), t))
        elif kind == "bin":
            name = draw(st.sampled_from(_BIN))
            vals.append(b.value(name, draw(st.sampled_from(vals)), draw(st.sampled_from(vals))))
        elif kind == "neg":
            vals.append(b.value("arith.neg", b.value("arith.neg", draw(st.sampled_from(vals)))))
        elif kind == "cmp_select":
            x, y = draw(st.sampled_from(vals)), draw(st.sampled_from(vals))
            c = b.value("arith.cmp", x, y, pred=draw(st.sampled_from(["lt", "eq", "ge"])))
            vals.append(b.value("arith.select", c, y, x))
        elif kind == "if" and depth < 2:
            x, y = draw(st.sampled_from(vals)), draw(st.sampled_from(vals))
            c = b.value("arith.cmp", x, y, pred="le")
            regions = []
            for _side in range(2):
                blk = Block()
                inner = {k: list(v) for k, v in pool.items()}
                with b.at_end(blk):
                    _build(draw, b, inner, depth + 1)
                    b.create("scf.yield", [inner[t][-1]])
                regions.append(Region(blk))
            vals.append(b.create("scf.if", [c], [t], regions=regions).result)


@st.composite
def programs(draw):
    m = Module()
    f = new_func(m, "f", [types.I32, types.F32], ["n", "x"], [types.I32, types.F32], "func")
    block = f.regions[0].block
    b = Builder(block)
    pool = {types.I32: [block.args[0]], types.F32: [block.args[1]]}
    _build(draw, b, pool, 0)
    b.create("func.return", [pool[types.I32][-1], pool[types.F32][-1]])
    verify_module(m)
    return m


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f" and np.isnan(a) and np.isnan(b):
        return True
    return a.dtype == b.dtype and a.tobytes() == b.tobytes()


@settings(max_examples=150, deadline=None)
@given(programs(), st.sampled_from([0, 3, -5, 2**31 - 1]), st.sampled_from([0.0, -0.0, 1.5, -2.0]))
def test_pipeline_preserves_results(module, n, x):
    func = module.funcs[0]
    args = (np.int32(n), np.float32(x))
    with np.errstate(all="ignore"):
        before = run_block(func.regions[0].block, args)
        run_pipeline(module, DEFAULT_PIPELINE.replace("inline,", ""))
        after = run_block(module.funcs[0].regions[0].block, args)
    assert all(_same(p, q) for p, q in zip(before, after)), (before, after)
