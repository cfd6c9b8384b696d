"""IR module -> one CUDA C translation unit.

The unit holds, in order: the pieces the module's ops asked for (types, then the
helpers that use them; nothing else, see ``emitter.Source``), prototypes of the
called functions, their definitions, then the kernels. A kernel is::

    extern "C" __global__ void __launch_bounds__(256) k_<name>_<n>(<params>, kd_grid kd_g
                                                                  [, long long *kd_err])

with one C parameter per kernel argument passed by value (arrays as descriptors),
then the launch grid (``kd_g.n`` threads; ``kd_g.dim`` the extents), then in debug
builds the error record. Each thread runs one index (an exact grid of 256-thread
blocks, no grid-stride loop): ``kd_i = blockIdx.x * blockDim.x + threadIdx.x``
(32-bit: launches are limited to 2**31 - 1 threads, like the cpu backend, since
``tid()`` is an ``int32``), and an n-d ``tid()`` is split from it row-major with
32-bit division. Array addresses are computed in 64 bits (``helpers.element_ptr``).
That is the general entry; release builds add a fast entry ``k_<name>_0_fast`` with
the same parameters where ``variants.fast_plan`` gives one (an n-d grid, 32-bit
offsets, ``__ldg`` loads), which a launch takes when ``geometry.fast_geometry``
allows it.

Every body line carries its op's source location: ``#line`` directives name the
user's Python file and line, so NVRTC messages point there. Statements of one
Python line share one C line; lines of kdsl's own code map back to the ``.cu``
unit itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from kdsl.backends.cuda.emitter import FuncEmitter, Source
from kdsl.backends.cuda.names import BLOCK as BLOCK  # re-exported: the names a hit needs
from kdsl.backends.cuda.names import UNIT_NAME as UNIT_NAME
from kdsl.backends.cuda.names import entry_name as entry_name
from kdsl.backends.cuda.names import fast_entry_name as fast_entry_name
from kdsl.backends.cuda.names import kernel_names as kernel_names
from kdsl.backends.cuda.names import tid_ndims as tid_ndims
from kdsl.backends.cuda.variants import FastPlan, fast_plan
from kdsl.errors import KdslCapabilityError
from kdsl.ir.core import Loc, Module, Operation

_GRID = "struct kd_grid { unsigned int n; unsigned int dim[4]; };"


@dataclass
class CudaSource:
    """Generated CUDA C, the C entry name of each kernel symbol, and of its fast entry
    (``variants``) where it has one."""

    text: str
    entries: dict[str, str]
    uses_f16: bool = False
    fast_entries: dict[str, str] = field(default_factory=dict)


def generate(
    module: Module, kernels: list[str], debug: bool = False, max_registers: int | None = None
) -> CudaSource:
    """The CUDA C unit holding ``kernels`` (and their callees); see the module docstring.
    ``max_registers`` (the kernel option ``cuda_max_registers``, Warp's): each entry is
    declared ``__maxnreg__(max_registers)`` instead of ``__launch_bounds__(BLOCK)``
    (CUDA takes one or the other)."""
    # The op table (every op's emitter, about 5 ms to import) only when code is generated:
    # a cache hit names its kernel (``entry_name``) without it.
    from kdsl.backends.cuda.ops import TABLE

    src = Source(module, TABLE, debug)
    src.need("kd_grid", lambda: _GRID)
    bodies: list[tuple[str, list]] = []
    entries = {}
    fast = {}
    for k in kernels:
        entries[k] = src.func_name(k)
        bodies.append(_kernel(src, module.get_func(k), max_registers=max_registers))
        plan = fast_plan(module, k, debug)
        if plan is not None:
            fast[k] = fast_entry_name(k)
            bodies.append(_kernel(src, module.get_func(k), plan, fast[k], max_registers))
    funcs: list[tuple[str, str, list]] = []
    done: set[str] = set()
    while len(done) < len(src.funcs_todo):
        name = next(n for n in src.funcs_todo if n not in done)
        done.add(name)
        if not module.has_func(name):
            raise KdslCapabilityError(f"call to unknown function '{name}'")
        funcs.append(_function(src, module.get_func(name)))
    return CudaSource(_assemble(src, funcs, bodies), entries, src.uses_f16, fast)


def without_fast_entries(text: str) -> str:
    """A generated unit ``text`` less its kernels' fast entries (their definitions run
    from the ``extern "C"`` head to the closing brace at the start of a line): the
    general entries as they read on their own, for inspection and tests."""
    out: list[str] = []
    skipping = False
    for ln in text.split("\n"):
        if not skipping and ln.startswith('extern "C"') and "_fast(" in ln:
            skipping = True
        if not skipping:
            out.append(ln)
        elif ln == "}":
            skipping = False
    return "\n".join(out)


def _params(em: FuncEmitter, func: Operation) -> list[str]:
    out = []
    for a in func.regions[0].block.args:
        name = em.fresh()
        em.bind(a, name)
        out.append(f"{em.ctype(a.type)} {name}")
    return out


def _kernel(
    src: Source, func: Operation, plan: FastPlan | None = None, name: str | None = None,
    max_registers: int | None = None,
) -> tuple[str, list]:  # fmt: skip
    """The head and body lines of kernel ``func``: its general entry, or with ``plan``
    its fast entry ``name`` (``variants``)."""
    em = FuncEmitter(src, func, is_kernel=True)
    params = _params(em, func) + ["kd_grid kd_g"]
    if src.debug:
        params.append("long long *kd_err")
    nds = sorted(n for n in tid_ndims(func) if n > 1)
    if len(nds) > 1:
        raise KdslCapabilityError(f"kernel uses tid() with {nds} dimensions at once", func.loc)
    if plan is not None:
        args = func.regions[0].block.args
        em.narrow = frozenset(args[i] for i, _, _ in plan.arrays)
        em.read_only = frozenset(args[i] for i in plan.read_only)
    if plan is not None and plan.grid_nd:
        _nd_grid_prologue(em, plan.grid_nd)
    else:
        _linear_prologue(em, nds)
    em.lower_block(func.regions[0].block)
    bound = (
        f"__launch_bounds__({BLOCK})" if max_registers is None else f"__maxnreg__({max_registers})"
    )
    head = (
        f'extern "C" __global__ void {bound} '
        f"{name or src.func_name(func.attrs['sym_name'])}({', '.join(params)})"
    )
    return head, em.lines


def _nd_grid_prologue(em: FuncEmitter, nd: int) -> None:
    """The thread index of an n-d grid: dim ``nd - 1`` along x, ``nd - 2`` along y..."""
    axes = "xyz"[:nd]
    for a in axes:
        em.line(f"const unsigned int kd_{a} = blockIdx.{a} * blockDim.{a} + threadIdx.{a};")
    outside = " || ".join(f"kd_{a} >= kd_g.dim[{nd - 1 - k}]" for k, a in enumerate(axes))
    em.line(f"if ({outside}) return;")
    em.tid_parts = [f"(int)kd_{axes[nd - 1 - d]}" for d in range(nd)]


def _linear_prologue(em: FuncEmitter, nds: list[int]) -> None:
    """The linear thread index ``kd_i``, and an n-d one split from it row-major."""
    em.line("const unsigned int kd_i = blockIdx.x * blockDim.x + threadIdx.x;")
    em.line("if (kd_i >= kd_g.n) return;")
    if nds:
        nd = nds[0]
        em.line("unsigned int kd_r = kd_i;")
        for d in range(nd - 1, 0, -1):
            em.line(f"const int kd_t{d} = (int)(kd_r % kd_g.dim[{d}]); kd_r /= kd_g.dim[{d}];")
        em.line("const int kd_t0 = (int)kd_r;")
        em.tid_parts = [f"kd_t{d}" for d in range(nd)]


def _function(src: Source, func: Operation) -> tuple[str, str, list]:
    em = FuncEmitter(src, func, is_kernel=False)
    res = list(func.attrs.get("res_types", []))
    if not res:
        em.ret_type = "void"
    elif len(res) == 1:
        em.ret_type = src.ctype(res[0])
    else:
        em.ret_type = src.ret_struct(res)
    params = _params(em, func)
    if src.debug:
        params.append("long long *kd_err")
    out = em.lower_block(func.regions[0].block)
    if not res:
        em.line("return;")
    elif len(res) == 1:
        em.line(f"return {out[0]};")
    else:
        em.line(f"return {em.ret_type}{{{', '.join(out)}}};")
    head = f"__device__ {em.ret_type} {src.func_name(func.attrs['sym_name'])}({', '.join(params)})"
    return head, head + ";", em.lines


def _escape(path: str) -> str:
    """``path`` as the body of a C string literal."""
    out = []
    for ch in path:
        if ch in '\\"':
            out.append("\\" + ch)
        elif " " <= ch <= "~":
            out.append(ch)
        else:
            out.append(f"\\x{ord(ch):02x}" if ord(ch) < 256 else "?")
    return "".join(out)


def _loc_ok(loc: Loc | None) -> bool:
    return loc is not None and bool(loc.file) and loc.line > 0


class _Writer:
    """Physical lines with ``#line`` bookkeeping (see the module docstring)."""

    def __init__(self) -> None:
        self.out: list[str] = []
        self.mapped: tuple[str, int] | None = None  # (file, line) the next line maps to

    def plain(self, text: str) -> None:
        if self.mapped is not None:
            self.out.append(f'#line {len(self.out) + 2} "{UNIT_NAME}"')
            self.mapped = None
        self.out.extend(text.split("\n"))

    def located(self, text: str, loc: Loc | None) -> None:
        if not _loc_ok(loc):
            self.plain(text)
            return
        if self.mapped != (loc.file, loc.line):
            self.out.append(f'#line {loc.line} "{_escape(loc.file)}"')
        self.out.append(text)
        self.mapped = (loc.file, loc.line + 1)

    def body(self, lines: list) -> None:
        """Body lines; consecutive statements of one source line share a C line."""
        i = 0
        while i < len(lines):
            depth, text, loc = lines[i]
            j = i + 1
            if _joinable(text):
                while (
                    j < len(lines)
                    and lines[j][0] == depth
                    and _same_line(lines[j][2], loc)
                    and _joinable(lines[j][1])
                ):
                    j += 1
            joined = " ".join(t for _, t, _ in lines[i:j])
            self.located("  " * depth + joined, loc)
            i = j


def _joinable(text: str) -> bool:
    return not text.endswith("{") and not text.startswith("}")


def _same_line(a: Loc | None, b: Loc | None) -> bool:
    if not (_loc_ok(a) and _loc_ok(b)):
        return False
    return a.file == b.file and a.line == b.line


def _assemble(src: Source, funcs: list, kernels: list) -> str:
    w = _Writer()
    w.plain("// CUDA C generated by kdsl's cuda backend; holds only what its kernels use.")
    for piece in src.pieces.values():
        w.plain(piece)
    for _, proto, _ in funcs:
        w.plain(proto)
    for head, _, lines in funcs:
        w.plain(head + " {")
        w.body(lines)
        w.plain("}")
    for head, lines in kernels:
        w.plain(head + " {")
        w.body(lines)
        w.plain("}")
    return "\n".join(w.out) + "\n"
