"""The structured form of a fuzzed kdsl program and its rendering as Python source.

A ``Program`` is a tree of statements (``Assign``, ``If``, ``For``, ``While``,
``Line``) whose expressions are source text already typed by the generator
(``kdsl.testing.fuzz.generate``), plus the input data and the prelude pieces
(structs, ``@func`` overloads) the body uses. Hypothesis shrinks the draws that
built the tree, so a failing program shrinks to fewer statements and smaller
expressions; ``Program.source()`` prints it as a standalone Python file that
defines the kernel and runs it (``python repro.py``).

The float type of a program is the module-level alias ``F``: the gradient check
renders the same program with ``F = wp.float64``.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Launch dimension of every fuzzed kernel, and the length of its array inputs.
N = 6
#: Length of the array-of-structs input.
M = 3
#: The marker the renderer appends to the line an invalid program's error must name.
MARK = "  # <- error here"

#: Prelude pieces, in the order they are defined; each lists the pieces it needs.
PRELUDE: dict[str, tuple[tuple[str, ...], str]] = {
    "Inner": ((), "@wp.struct\nclass Inner:\n    w: F\n    k: wp.int16\n"),
    "Params": (
        ("Inner",),
        "@wp.struct\nclass Params:\n    a: F\n    v: V3\n    n: wp.int32\n    inner: Inner\n",
    ),
    "g": (
        (),
        "@wp.func\ndef g(x: F, y: F):\n    return x * y + F(0.5)\n\n\n"
        "@wp.func\ndef g(x: wp.int32, y: wp.int32):\n    return x * y - wp.int32(1)\n\n\n"
        "@wp.func\ndef g(x: V3, y: F):\n    return x * y\n",
    ),
    "gloop": (
        (),
        "@wp.func\ndef gloop(x: F, n: wp.int32):\n    acc = x\n    for k in range(n):\n"
        "        if acc > F(4.0):\n            return acc\n        acc = acc * F(0.75) + F(1.0)\n"
        "    return acc\n",
    ),
    "sf": (
        ("Params",),
        "@wp.func\ndef sf(s: Params, x: F):\n    return s.a * x + s.inner.w + s.v[1]\n",
    ),
}


@dataclass(frozen=True)
class Line:
    """One line of kernel code (an expression statement, ``break``, ``return``...)."""

    text: str

    def render(self, indent: str) -> list[str]:
        return [indent + self.text]


@dataclass(frozen=True)
class Assign:
    """``target = expr`` or ``target op= expr``."""

    target: str
    expr: str
    op: str = ""

    def render(self, indent: str) -> list[str]:
        return [f"{indent}{self.target} {self.op}= {self.expr}"]


@dataclass(frozen=True)
class If:
    """``if cond:`` with a body and an optional ``else``."""

    cond: str
    body: tuple
    orelse: tuple = ()

    def render(self, indent: str) -> list[str]:
        lines = [f"{indent}if {self.cond}:", *_block(self.body, indent + "    ")]
        if self.orelse:
            lines += [f"{indent}else:", *_block(self.orelse, indent + "    ")]
        return lines


@dataclass(frozen=True)
class For:
    """``for var in range(args):`` (static when ``args`` is constant)."""

    var: str
    args: str
    body: tuple

    def render(self, indent: str) -> list[str]:
        return [
            f"{indent}for {self.var} in range({self.args}):",
            *_block(self.body, indent + "    "),
        ]


@dataclass(frozen=True)
class While:
    """A ``while`` loop bounded by a counter incremented first (so ``continue`` ends)."""

    counter: str
    bound: str
    body: tuple

    def render(self, indent: str) -> list[str]:
        inner = indent + "    "
        return [
            f"{indent}{self.counter} = wp.int32(0)",
            f"{indent}while {self.counter} < {self.bound}:",
            f"{inner}{self.counter} = {self.counter} + wp.int32(1)",
            *_block(self.body, inner),
        ]


def _block(stmts: tuple, indent: str) -> list[str]:
    lines: list[str] = []
    for s in stmts:
        lines += s.render(indent)
    return lines or [indent + "pass"]


@dataclass(frozen=True)
class Inputs:
    """The values every fuzzed kernel's parameters take (NumPy-free, so reprs stay short)."""

    xs: tuple[float, ...]
    ns: tuple[int, ...]
    pa: float = 0.5
    pv: tuple[float, float, float] = (0.25, -1.0, 2.0)
    pn: int = 3
    pw: float = -0.75
    pk: int = 2


@dataclass(frozen=True)
class Program:
    """A fuzzed kernel: its float type, body, results, prelude and inputs."""

    ftype: str
    body: tuple
    result_f: str
    result_i: str
    uses: frozenset[str]
    inputs: Inputs
    differentiable: bool
    #: For invalid programs: what was broken (None for a valid program).
    invalid: str | None = None
    #: Extra lines after the kernel (an invalid program's bad launch).
    launch_override: str | None = None

    def prelude(self) -> list[str]:
        """The prelude pieces the program uses, with what they need, in definition order."""
        need: set[str] = set()

        def add(name: str) -> None:
            if name not in need:
                need.add(name)
                for dep in PRELUDE[name][0]:
                    add(dep)

        for name in self.uses | {"Params"}:  # the kernel always takes a Params
            add(name)
        return [PRELUDE[name][1] for name in PRELUDE if name in need]

    def kernel_lines(self) -> list[str]:
        """The ``@wp.kernel`` definition, line by line."""
        lines = [
            "@wp.kernel",
            "def fuzz_kernel(xs: wp.array(dtype=F), ns: wp.array(dtype=wp.int32), p: Params,",
            "                ps: wp.array(dtype=Params), out: wp.array(dtype=F),",
            "                iout: wp.array(dtype=wp.int32), acc: wp.array(dtype=F),",
            "                iacc: wp.array(dtype=wp.int32)):",
            "    i = wp.tid()",
        ]
        lines += _block(self.body, "    ")
        lines += [f"    out[i] = {self.result_f}", f"    iout[i] = {self.result_i}"]
        return lines

    def source(self, ftype: str | None = None) -> str:
        """The program as a standalone Python file (``ftype`` overrides the float type)."""
        head = [
            f'"""A kdsl fuzzer program{f" ({self.invalid})" if self.invalid else ""}."""',
            "",
            "import numpy as np",
            "",
            "import kdsl as wp",
            "",
            f"F = wp.{ftype or self.ftype}",
            "V3 = wp.vector(3, F)",
            "M33 = wp.matrix((3, 3), F)",
            "Q = wp.quaternion(F)",
            "TF = wp.transformation(F)",
            "",
        ]
        parts = [*head]
        for piece in self.prelude():
            parts += ["", piece]
        parts += ["", *self.kernel_lines(), "", "", *self.runner_lines()]
        return "\n".join(parts) + "\n"

    def runner_lines(self) -> list[str]:
        """``make_args`` and ``run``: the program's inputs and a launch on one backend."""
        a = self.inputs
        launch = self.launch_override or (
            "wp.launch(fuzz_kernel, dim=N, inputs=args, device=device, backend=backend)"
        )
        return [
            f"N = {N}",
            "",
            "",
            "def make_args(requires_grad=False, device='cpu'):",
            '    """The kernel\'s arguments, in order (outputs zeroed)."""',
            "    dt = wp.dtype_to_numpy(F)",
            f"    xs = wp.array(np.array({list(a.xs)!r}, dtype=dt), dtype=F, requires_grad=requires_grad, device=device)",
            f"    ns = wp.array(np.array({list(a.ns)!r}, dtype=np.int32), dtype=wp.int32, device=device)",
            "    p = Params()",
            f"    p.a, p.v, p.n = F({a.pa!r}), V3({a.pv[0]!r}, {a.pv[1]!r}, {a.pv[2]!r}), {a.pn}",
            f"    p.inner.w, p.inner.k = F({a.pw!r}), wp.int16({a.pk})",
            f"    ps = wp.array([p] * {M}, dtype=Params, device=device)",
            "    out = wp.zeros(N, dtype=F, requires_grad=requires_grad, device=device)",
            "    iout = wp.zeros(N, dtype=wp.int32, device=device)",
            "    acc = wp.zeros(3, dtype=F, requires_grad=requires_grad, device=device)",
            "    iacc = wp.zeros(3, dtype=wp.int32, device=device)",
            "    return [xs, ns, p, ps, out, iout, acc, iacc]",
            "",
            "",
            "def run(backend, args=None):",
            '    """Launch the kernel on ``backend``; returns its argument list."""',
            "    device = 'cuda' if backend == 'cuda' else 'cpu'",
            "    args = make_args(device=device) if args is None else args",
            f"    {launch}",
            "    return args",
            "",
            "",
            'if __name__ == "__main__":',
            '    for name in ("interp", "cpu"):',
            "        got = run(name)",
            "        print(name, got[4].numpy(), got[5].numpy(), got[6].numpy(), got[7].numpy())",
        ]
