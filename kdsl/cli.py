"""The ``kdsl`` command line (also ``python -m kdsl``).

Commands::

    kdsl ir FILE.py[:KERNEL] [--stage NAME] [--backend NAME] [--pipeline P] ...
    kdsl opt FILE.kir -p PIPELINE [--print-after-all] [--time-passes] [--debuginfo]
    kdsl backends
    kdsl pipeline [BACKEND]
    kdsl conformance --backend NAME [-k EXPR] [-x]
    kdsl cache info|clear
    kdsl scene list|run|stability|info [NAME] ...

A user mistake (a missing file, a kernel that does not compile, a bad pipeline, an
unknown stage or backend) prints kdsl's message, with the file, line and a caret,
to stderr and exits with status 2; ``KDSL_TRACEBACK=full`` shows the Python
traceback instead. See docs/cli.md.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kdsl.errors import KdslError, full_tracebacks

#: Exit status of a user error (bad input), as argparse uses for bad arguments.
EXIT_USAGE = 2
#: Exit status of an internal error (a kdsl bug).
EXIT_INTERNAL = 1
#: Exit status of a conformance run with a failed case, or one that tested nothing.
EXIT_FAILED = 1

#: Stages every backend shares: the frontend's IR and the IR after the pipeline.
KIR, KIR_OPT = "kir", "kir-opt"
#: The kernel's adjoint (and tape counter) after the pipeline.
ADJOINT = "adjoint"


class CliError(KdslError):
    """A bad command-line input that is not about kernel source (no location)."""


# --------------------------------------------------------------------------- loading


def load_user_module(path: str) -> Any:
    """Import the Python file ``path`` as a module, with its directory on sys.path."""
    file = Path(path)
    if not file.is_file():
        raise CliError(f"no such file: {path}")
    directory = str(file.resolve().parent)
    if directory not in sys.path:
        sys.path.insert(0, directory)
    name = f"_kdsl_user_{file.stem}"
    spec = importlib.util.spec_from_file_location(name, file)
    if spec is None or spec.loader is None:
        raise CliError(f"cannot import {path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    # Registered so frontends that look kernels' modules up by name find it.
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except KdslError:
        raise
    except SyntaxError as e:
        # The message first, then Python's own file/line/caret rendering.
        *where, what = traceback.format_exception_only(e)
        raise CliError(what.rstrip() + "\n" + "".join(where).rstrip()) from None
    except Exception as e:
        raise CliError(_user_exception(path, e)) from None
    return module


def _user_exception(path: str, e: BaseException) -> str:
    """One message for an exception raised by the user's module: where and what."""
    frames = [f for f in traceback.extract_tb(e.__traceback__) if f.filename == str(Path(path))]
    where = ""
    if frames:
        f = frames[-1]
        where = f'\n  File "{f.filename}", line {f.lineno}\n    {f.line}'
    return f"error while importing {path}: {type(e).__name__}: {e}{where}"


def is_kernel(obj: Any) -> bool:
    """True for a ``@kdsl.kernel`` object (anything that builds an IR module)."""
    return (
        not isinstance(obj, type)
        and callable(getattr(obj, "build_module", None))
        and hasattr(obj, "arg_names")
    )


def find_kernels(module: Any, name: str | None, path: str | None = None) -> list[Any]:
    """The kernels defined in ``module`` (all of them, or the one called ``name``).

    ``path`` is the file as the user named it, for messages.
    """
    path = path or module.__file__
    kernels: dict[int, Any] = {}
    for attr, obj in vars(module).items():
        if is_kernel(obj) and not attr.startswith("__"):
            kernels.setdefault(id(obj), obj)
    found = list(kernels.values())
    if name is None:
        if not found:
            raise CliError(f"{path} defines no @kdsl.kernel")
        return found
    named = [k for k in found if getattr(k, "name", None) == name]
    if not named and is_kernel(getattr(module, name, None)):
        named = [getattr(module, name)]
    if not named:
        known = ", ".join(sorted(str(getattr(k, "name", "?")) for k in found)) or "none"
        raise CliError(f"{path} has no kernel named {name!r} (kernels: {known})")
    return named[:1]


def split_target(target: str) -> tuple[str, str | None]:
    """``"sim.py:step"`` -> ``("sim.py", "step")``; ``"sim.py"`` -> ``("sim.py", None)``."""
    path, sep, kernel = target.rpartition(":")
    if sep and path.endswith(".py") and kernel.isidentifier():
        return path, kernel
    return target, None


# --------------------------------------------------------------------------- commands


def _check_pipeline(pipeline: str) -> None:
    from kdsl.passes import parse_pipeline

    try:
        parse_pipeline(pipeline)
    except ValueError as e:
        raise CliError(f"bad pipeline: {e}") from None


def _default_backend() -> str:
    from kdsl.runtime.launch import default_backend_for

    return default_backend_for("cpu")


def _stages(backend: Any) -> list[str]:
    """Every stage ``kdsl ir`` can print for ``backend``, in pipeline order."""
    own = (KIR, KIR_OPT, ADJOINT)
    return [KIR, KIR_OPT, ADJOINT, *(s for s in backend.stages() if s not in own)]


def _backend(name: str | None) -> Any:
    from kdsl.backends.registry import get_backend

    return get_backend(name or _default_backend())


def cmd_ir(args: argparse.Namespace) -> int:
    """``kdsl ir``: print a kernel's IR at a stage, its pass dumps, or its features."""
    path, kernel_name = split_target(args.target)
    module = load_user_module(path)
    kernels = find_kernels(module, kernel_name, path)
    own = (KIR, KIR_OPT, ADJOINT)
    backend = _backend(args.backend) if args.backend or args.stage not in own else None
    if args.stage not in own and args.stage not in backend.stages():
        stages = ", ".join(_stages(backend))
        raise CliError(f"backend {backend.name!r} has no stage {args.stage!r} (stages: {stages})")
    if args.pipeline is not None:
        pipeline = args.pipeline
    else:
        pipeline = backend.pipeline if backend is not None else _backend(None).pipeline
    _check_pipeline(pipeline)
    for i, kernel in enumerate(kernels):
        if len(kernels) > 1:
            print(f"{'' if i == 0 else chr(10)}// kernel {kernel.name}")
        sys.stdout.write(_kernel_ir(kernel, args, backend, pipeline))
    return 0


def _kernel_ir(kernel: Any, args: argparse.Namespace, backend: Any, pipeline: str) -> str:
    from kdsl.ir import print_module
    from kdsl.passes import run_pipeline

    if args.stage == ADJOINT:
        from kdsl.compiler import adjoint_module

        ir = adjoint_module(kernel)
        ir.get_func(kernel.key).erase()
        run_pipeline(ir, pipeline, print_after_all=args.print_after_all,
                     time_passes=args.time_passes, out=sys.stdout, debuginfo=args.debuginfo)  # fmt: skip
        return _features(ir) if args.features else print_module(ir, debuginfo=args.debuginfo)
    ir = kernel.build_module()
    if args.stage == KIR and not args.features:
        return print_module(ir, debuginfo=args.debuginfo)
    if args.stage != KIR:
        run_pipeline(ir, pipeline, print_after_all=args.print_after_all,
                     time_passes=args.time_passes, out=sys.stdout, debuginfo=args.debuginfo)  # fmt: skip
    if args.features:
        return _features(ir)
    if args.stage == KIR_OPT:
        return print_module(ir, debuginfo=args.debuginfo)
    from kdsl.compiler import lower

    text = lower(backend, ir, args.stage, prepared=True)
    return text if text.endswith("\n") else text + "\n"


def _features(ir: Any) -> str:
    """The feature analysis of ``ir``, as ``kdsl ir --features`` prints it."""
    from kdsl.passes.features import analyze_features

    return analyze_features(ir).summary()


def cmd_opt(args: argparse.Namespace) -> int:
    """``kdsl opt``: parse IR text, run a pipeline, print the result."""
    from kdsl.tools.opt import run_opt

    if args.file == "-":
        text, file = sys.stdin.read(), "<stdin>"
    else:
        if not Path(args.file).is_file():
            raise CliError(f"no such file: {args.file}")
        text, file = Path(args.file).read_text(), args.file
    _check_pipeline(args.pipeline)
    out = run_opt(text, args.pipeline, file=file, print_after_all=args.print_after_all,
                  time_passes=args.time_passes, debuginfo=args.debuginfo,
                  verify_each=not args.no_verify)  # fmt: skip
    sys.stdout.write(out)
    return 0


def cmd_backends(args: argparse.Namespace) -> int:
    """``kdsl backends``: every backend with its version, devices and capabilities."""
    from kdsl.backends.registry import available_backends, get_backend, load_failures

    for name in available_backends():
        b = get_backend(name)
        print(f"{name} {b.version}")
        print(f"  devices:      {', '.join(b.devices()) or '(none)'}")
        print(f"  capabilities: {', '.join(sorted(b.capabilities)) or '(none)'}")
        print(f"  stages:       {', '.join(_stages(b))}")
        print(f"  pipeline:     {b.pipeline}")
    failures = load_failures()
    for name, message in sorted(failures.items()):
        print(f"{name} FAILED TO LOAD: {message}")
    return 0


def cmd_pipeline(args: argparse.Namespace) -> int:
    """``kdsl pipeline``: the pass pipeline a backend runs, as ``kdsl opt -p`` text."""
    print(_backend(args.backend).pipeline)
    return 0


class _Tally:
    """A pytest plugin object that counts outcomes of the conformance run."""

    def __init__(self) -> None:
        self.passed = self.failed = self.skipped = 0

    def pytest_runtest_logreport(self, report: Any) -> None:
        if report.when == "call" and report.passed:
            self.passed += 1
        elif report.failed:
            self.failed += 1
        elif report.skipped:
            self.skipped += 1

    def pytest_collectreport(self, report: Any) -> None:
        if report.failed:
            self.failed += 1

    def summary(self) -> str:
        line = f"{self.passed} passed, {self.failed} failed"
        return line + (f", {self.skipped} skipped" if self.skipped else "")


def cmd_conformance(args: argparse.Namespace) -> int:
    """``kdsl conformance``: run the packaged suite on one backend.

    Exits 0 when at least one case passed and none failed; 1 when a case failed or
    nothing was tested (the backend has no device here, every case was skipped, or
    ``-k`` matched none), with the reason on stderr; 2 for an unknown backend.
    """
    import pytest

    argv = ["--pyargs", "kdsl.testing", "-p", "kdsl.testing.plugin",
            f"--kdsl-backend={args.backend}", "-q", "-p", "no:cacheprovider"]  # fmt: skip
    if args.k:
        argv += ["-k", args.k]
    if args.exitfirst:
        argv.append("-x")
    backend = _backend(args.backend)  # an unknown or broken backend is a user error
    if not backend.devices():
        return _nothing_ran(f"the {backend.name} backend has no device on this machine")
    tally = _Tally()
    code = pytest.main(argv, plugins=[tally])
    print(tally.summary())
    clean = code in (pytest.ExitCode.OK, pytest.ExitCode.NO_TESTS_COLLECTED)
    if not clean or tally.failed:
        return EXIT_FAILED
    if tally.passed == 0:
        if tally.skipped:
            return _nothing_ran(f"all {tally.skipped} selected cases were skipped")
        return _nothing_ran(f"no case matches -k {args.k!r}" if args.k else "no case was collected")
    return 0


def _nothing_ran(reason: str) -> int:
    """Report a conformance run that tested nothing: a failure, never a green run."""
    print(f"kdsl conformance: nothing was tested: {reason}", file=sys.stderr)
    return EXIT_FAILED


def cmd_cache(args: argparse.Namespace) -> int:
    """``kdsl cache info|clear``: show or empty the kernel cache directory."""
    from kdsl.compiler.cache import DiskCache, cache_dir, check_directory, disk_cache_enabled

    directory = cache_dir()
    # An unsafe directory (not ours, or writable by others) is never emptied.
    unsafe = check_directory(directory, create=False) if directory.exists() else None
    disk = DiskCache(directory)
    if args.action == "clear":
        if unsafe is not None:
            raise CliError(f"refusing to clear the kernel cache: {unsafe}")
        count, size = disk.clear()
        print(f"removed {count} entries ({size} bytes) from {directory}")
        return 0
    info = disk.info()
    print(f"directory: {info.directory}")
    print(f"entries:   {info.entries}")
    print(f"size:      {info.total_bytes} bytes")
    if unsafe is not None or not disk_cache_enabled():
        print(f"disabled:  {unsafe or 'KDSL_CACHE is off'}")
    return 0


# --------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of every command."""
    parser = argparse.ArgumentParser(prog="kdsl", description="kdsl: a Python kernel DSL.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("ir", help="print a kernel's IR or target code at any stage")
    p.add_argument("target", metavar="FILE.py[:KERNEL]")
    p.add_argument("--stage", default=KIR_OPT,
                   help="kir (frontend output), kir-opt (after the pipeline; default), "
                        "or a backend stage (see `kdsl backends`)")  # fmt: skip
    p.add_argument("--backend", help="backend whose pipeline and stages to use")
    p.add_argument("--pipeline", help="pass pipeline instead of the backend's")
    p.add_argument("--print-after-all", action="store_true", help="dump the IR after each pass")
    p.add_argument("--debuginfo", action="store_true", help="print source locations")
    p.add_argument("--time-passes", action="store_true", help="print the time of each pass")
    p.add_argument(
        "--features", action="store_true", help="print the feature analysis (what backends emit)"
    )
    p.set_defaults(run=cmd_ir)

    p = sub.add_parser("opt", help="run a pass pipeline over an IR file")
    p.add_argument("file", metavar="FILE.kir", help="IR text file, or - for stdin")
    p.add_argument("-p", "--pipeline", required=True, help='e.g. "inline,fold,cse,dce"')
    p.add_argument("--print-after-all", action="store_true", help="dump the IR after each pass")
    p.add_argument("--time-passes", action="store_true", help="print the time of each pass")
    p.add_argument("--debuginfo", action="store_true", help="print source locations")
    p.add_argument("--no-verify", action="store_true", help="do not verify after each pass")
    p.set_defaults(run=cmd_opt)

    p = sub.add_parser("backends", help="list backends, devices, capabilities, load failures")
    p.set_defaults(run=cmd_backends)

    p = sub.add_parser("pipeline", help="print the pass pipeline a backend runs")
    p.add_argument("backend", nargs="?", help="backend name (default: the cpu device's)")
    p.set_defaults(run=cmd_pipeline)

    p = sub.add_parser("conformance", help="run the conformance suite on a backend")
    p.add_argument("--backend", required=True, help="backend to test")
    p.add_argument("-k", metavar="EXPR", help="only cases matching this pytest -k expression")
    p.add_argument("-x", "--exitfirst", action="store_true", help="stop at the first failure")
    p.set_defaults(run=cmd_conformance)

    p = sub.add_parser("cache", help="show (info) or empty (clear) the kernel cache")
    p.add_argument("action", choices=["info", "clear"])
    p.set_defaults(run=cmd_cache)

    from kdsl.scenes.cli import add_scene_parser  # docs/scenes.md

    add_scene_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``kdsl`` command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.run(args))
    except KdslError as e:
        if full_tracebacks():
            raise
        print(f"kdsl: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        # The reader went away (`kdsl backends | head`): not an error of ours. Point
        # stdout at /dev/null so the interpreter's final flush does not fail again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except Exception as e:
        if full_tracebacks():
            raise
        print(f"kdsl: internal error: {type(e).__name__}: {e}\n"
              "  (this is a kdsl bug; set KDSL_TRACEBACK=full for the traceback)",
              file=sys.stderr)  # fmt: skip
        return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
