"""Hypothesis strategies for invalid fuzzed programs (``invalid_programs()``).

Each takes a small valid program and breaks it one way: a type mismatch, a read of a
name that may be unassigned, Python the kernel language does not accept, an
undefined name, or a launch with the wrong arguments. The broken line carries
``program.MARK``: ``check.check_invalid`` expects kdsl's error to name that line.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from hypothesis import strategies as st

from kdsl.testing.fuzz.generate import programs
from kdsl.testing.fuzz.program import MARK, Assign, If, Line, Program

#: Statements kdsl must reject, by the kind of mistake (each is valid Python).
BAD_LINES: dict[str, tuple[str, ...]] = {
    "type mismatch": (
        "bad = xs[i] + wp.int32(1)",
        "bad = V3(F(1.0), F(2.0), F(3.0)) + xs[i]",
        "bad = wp.cross(V3(F(1.0), F(2.0), F(3.0)), xs[i])",
        "bad = g(xs[i], wp.int8(1))",
        "bad = wp.dot(xs[i], xs[i])",
        "bad = wp.identity(n=3, dtype=F) * V3(F(1.0), F(2.0), F(3.0)) + xs[i]",
        "bad = p.a + p.n",
        "bad = wp.int8(1) + wp.int16(2)",
        "bad = xs[i] + wp.float64(1.0)",
        "bad = p.missing_field",
        "bad = ns[i] and xs",
    ),
    "unsupported syntax": (
        "bad = [xs[i], xs[i]]",
        "bad = lambda z: z",
        "bad = {i: xs[i]}",
        "bad = {i}",
        "bad = (xs[i] for k in range(3))",
        "bad = [xs[i] for k in range(3)]",
        "import math",
        "global N",
        "bad = f'{i}'",
        "bad = yield i",
        "del i",
        "bad = xs[i:]",
        "bad = (i, xs[i])[2]",
    ),
    "undefined name": (
        "bad = undefined_name + F(1.0)",
        "bad = np.sin(xs[i])",
        "bad = wp.not_a_builtin(xs[i])",
    ),
}

#: Launch calls with wrong arguments (``run``'s launch line is replaced).
BAD_LAUNCHES: tuple[str, ...] = (
    "wp.launch(fuzz_kernel, dim=N, inputs=args[:-1], device=device, backend=backend)",
    "wp.launch(fuzz_kernel, dim=N, inputs=[args[1], *args[1:]], device=device, backend=backend)",
    "wp.launch(fuzz_kernel, dim=N, inputs=[*args[:2], F(1.0), *args[3:]], device=device, backend=backend)",
    "wp.launch(fuzz_kernel, dim=N, inputs=[*args[:7], 5], device=device, backend=backend)",
    "wp.launch(fuzz_kernel, dim=N, inputs=[*args, args[0]], device=device, backend=backend)",
    "wp.launch(fuzz_kernel, dim=N, inputs=[*args[:4], args[5], args[5], *args[6:]], device=device, backend=backend)",
    "wp.launch(fuzz_kernel, dim=N, inputs=args, device=device, backend='no_such_backend')",
    "wp.launch(fuzz_kernel, dim=N, inputs=[args[0].reshape((2, 3)), *args[1:]], device=device, backend=backend)",
)


def _insert(body: tuple, at: int, stmts: tuple) -> tuple:
    at = min(at, len(body))
    return body[:at] + stmts + body[at:]


@st.composite
def invalid_programs(draw: Any) -> Program:
    """A small valid program broken in one place (see the module docstring)."""
    base = draw(programs(max_depth=1, max_stmts=3, differentiable=False))
    kind = draw(st.sampled_from([*BAD_LINES, "possibly unassigned", "bad launch"]))
    at = draw(st.integers(0, len(base.body)))
    uses = base.uses
    if kind == "bad launch":
        launch = draw(st.sampled_from(BAD_LAUNCHES)) + MARK
        return replace(base, invalid=kind, launch_override=launch)
    if kind == "possibly unassigned":
        stmts = (
            If("xs[i] > F(0.0)", (Assign("maybe", "xs[i] * F(2.0)"),)),
            Line("bad = maybe + F(1.0)" + MARK),
        )
    else:
        line = draw(st.sampled_from(BAD_LINES[kind]))
        if line.startswith("bad = g("):
            uses = uses | {"g"}
        stmts = (Line(line + MARK),)
    return replace(base, body=_insert(base.body, at, stmts), uses=uses, invalid=kind)
