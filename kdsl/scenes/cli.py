"""``kdsl scene list | run | stability | info | sweep | extremes`` (wired into ``kdsl.cli``; docs/scenes.md).

Bad input (an unknown scene, integrator, precision or backend, a dt that is not a
finite positive number) raises ``SceneError``, which ``kdsl.cli`` prints as
``kdsl: error: ...`` with exit status 2. ``--json`` files are written to a temporary
file and renamed, so they appear whole or not at all.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

from kdsl.scenes import scene_class, scene_names
from kdsl.scenes.base import PRECISIONS, check_choice, check_dt
from kdsl.scenes.binding import SceneError


def write_json(path: str, data: Any) -> None:
    """Write ``data`` to ``path`` atomically (a temporary file in its directory, renamed)."""
    target = Path(path)
    if not target.parent.is_dir():
        raise SceneError(f"cannot write {path}: no directory {target.parent}")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=2, default=_jsonable)
            f.write("\n")
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would outlive the rename
        os.replace(tmp, target)
    except BaseException:
        os.unlink(tmp)
        raise


def _jsonable(x: Any) -> Any:
    return float(x) if hasattr(x, "__float__") else str(x)


def _params(items: list[str] | None) -> dict[str, Any]:
    """``["count=8", "damping=0.5"]`` -> ``{"count": 8, "damping": 0.5}``."""
    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise SceneError(f"--param takes NAME=VALUE, not {item!r}")
        try:
            out[key] = int(value)
        except ValueError:
            try:
                out[key] = float(value)
            except ValueError:
                raise SceneError(f"--param {key}: {value!r} is not a number") from None
    return out


def _fmt(x: float | None, spec: str = ".3g") -> str:
    if x is None:
        return "-"
    return "inf" if math.isinf(x) else format(x, spec)


def cmd_list(args: argparse.Namespace) -> int:
    """``kdsl scene list``: each scene with its summary and integrators."""
    for name in scene_names():
        cls = scene_class(name)
        print(f"{name:10s} {cls.summary}")
        print(f"{'':10s} integrators: {', '.join(cls.integrators)}")
        params = ", ".join(f"{k}={v}" for k, v in cls.defaults.items())
        print(f"{'':10s} parameters: {params}; dt={cls.default_dt:g}, steps={cls.default_steps}")
    return 0


def _scene(args: argparse.Namespace, integrator: str | None = None) -> Any:
    from kdsl.scenes.measure import make_scene

    cls = scene_class(args.name)
    integ = integrator or args.integrator
    if integ is not None:
        check_choice(f"integrator for scene {args.name!r}", integ, cls.integrators)
    return make_scene(args.name, args.precision, integ, args.backend, **_params(args.param))


def cmd_run(args: argparse.Namespace) -> int:
    """``kdsl scene run``: wall time (compile apart), time per step, error."""
    from kdsl.scenes.measure import run_scene

    pictures = args.render is not None or args.usd is not None
    if pictures:  # before any work: bad paths and missing extras exit 2
        from kdsl.scenes import render

        render.check_outputs(args.render, args.usd, args.frames)
    scene = _scene(args)
    dt = check_dt(args.dt if args.dt is not None else scene.default_dt)
    steps = args.steps if args.steps is not None else scene.default_steps
    r = run_scene(scene, dt, steps, args.backend)
    print(
        f"scene {r.scene}  backend {r.backend}  precision {r.precision}  "
        f"integrator {r.integrator}  dt {r.dt:g}  steps {r.steps}  t_end {r.t_end:g}"
    )
    print(f"compile    {r.compile_s:.4f} s  (first step; {r.kernels_compiled} kernels compiled)")
    print(f"run        {r.wall_s:.4f} s  ({r.step_us:.1f} us/step)")
    print(f"error      {r.error:.3e}  ({r.error_what}, float64 reference)")
    if r.pde_error is not None:
        print(f"pde error  {r.pde_error:.3e}  (against the continuous PDE: time and grid)")
    if r.energy_drift is not None:
        print(f"energy     {r.energy_drift:+.3e}  (relative change over the run)")
    for what, value in r.extra.items():
        print(f"{what:10s} {value:.3e}")
    if args.json:
        write_json(args.json, r.as_dict())
    if pictures:  # a second, untimed run from the start, keeping --frames states
        animated = args.usd or Path(args.render).suffix.lower() == ".gif"
        frames = render.record(scene, dt, steps, args.frames if animated else 1)
        if args.render:
            render.write_image(args.render, frames)
            print(f"picture    {args.render}  ({render.IMAGE_SUFFIXES[Path(args.render).suffix.lower()]}"
                  f", {len(frames)} frames recorded)")  # fmt: skip
        if args.usd:
            render.write_usd(args.usd, frames)
            print(f"usd        {args.usd}  ({len(frames)} frames)")
    return 0


def cmd_stability(args: argparse.Namespace) -> int:
    """``kdsl scene stability``: largest stable dt per integrator and precision, and drift."""
    from kdsl.scenes.measure import GROWTH_BOUND, stability

    cls = scene_class(args.name)
    integrators = args.integrator.split(",") if args.integrator else list(cls.integrators)
    for integ in integrators:
        check_choice(f"integrator for scene {args.name!r}", integ, cls.integrators)
    precisions = args.precision.split(",") if args.precision else ["f16", "f32", "f64"]
    for p in precisions:
        check_choice("precision", p, list(PRECISIONS))
    if args.dt is not None:
        check_dt(args.dt)
    results = stability(args.name, integrators, precisions, args.horizon, args.drift_steps,
                        args.dt, args.backend, **_params(args.param))  # fmt: skip
    print(
        f"scene {args.name}: stable = finite, energy < {GROWTH_BOUND:g}x its start over "
        f"{args.horizon} steps; dt_max by bisection to 5%; drift over {args.drift_steps} "
        f"steps at dt {results[0].drift_dt:g}"
    )
    print(f"{'integrator':18s}{'prec':6s}{'dt_max':>11s}{'theory':>11s}{'ratio':>8s}{'drift':>12s}")
    for r in results:
        dt = _fmt(r.dt_max) + (" <" if r.bound == "above" else "")
        if r.bound == "below":
            dt = "none"
        ratio = (r.dt_max / r.theory if r.dt_max and r.theory and math.isfinite(r.theory)
                 and r.bound == "measured" else None)  # fmt: skip
        theory = "never" if r.theory == 0.0 else _fmt(r.theory)  # no dt is stable
        print(
            f"{r.integrator:18s}{r.precision:6s}{dt:>11s}{theory:>11s}"
            f"{_fmt(ratio, '.3f'):>8s}{_fmt(r.drift, '+.2e'):>12s}"
        )
        if r.blowup:
            print(f"  blow-up {r.blowup}")
    print(
        "(dt_max '<': stable at every dt tried, up to 1e4x the start; 'none': at none; "
        "theory 'never': no dt is stable, 'inf': every dt is)"
    )
    if args.json:
        write_json(args.json, [r.as_dict() for r in results])
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    """``kdsl scene info``: per kernel the ops, features, adjoint, code size, compile time."""
    from kdsl.scenes.measure import compile_info

    scene = _scene(args)
    infos = compile_info(scene, args.dt if args.dt is not None else scene.default_dt)
    print(
        f"scene {args.name}  backend {args.backend}  precision {scene.precision}  "
        f"integrator {scene.integrator}"
    )
    print(f"{'kernel':32s}{'ops':>6s}{'adjoint':>9s}{'code':>9s}{'compile':>10s}  features")
    for k in infos:
        code = "-" if k.code_bytes is None else str(k.code_bytes)
        print(
            f"{k.kernel:32s}{k.ops:>6d}{'yes' if k.adjoint else 'no':>9s}{code:>9s}"
            f"{k.compile_s:>9.3f}s  {', '.join(k.features) or '-'}"
        )
    total_code = sum(k.code_bytes or 0 for k in infos)
    print(
        f"{'total (' + str(len(infos)) + ' kernels)':32s}{sum(k.ops for k in infos):>6d}"
        f"{sum(k.adjoint for k in infos):>9d}{total_code:>9d}"
        f"{sum(k.compile_s for k in infos):>9.3f}s"
    )
    if args.json:
        write_json(args.json, [k.as_dict() for k in infos])
    return 0


def _list_arg(value: str | None, default: list[str], what: str, choices: Any) -> list[str]:
    items = value.split(",") if value else default
    for item in items:
        check_choice(what, item, list(choices))
    return items


def cmd_sweep(args: argparse.Namespace) -> int:
    """``kdsl scene sweep``: dt x precision x integrator x backend, table, JSON, plot."""
    from kdsl.scenes import sweep as sw
    from kdsl.scenes.measure import available_backends

    cls = scene_class(args.name)
    integrators = _list_arg(args.integrator, list(cls.integrators), f"integrator for scene "
                            f"{args.name!r}", cls.integrators)  # fmt: skip
    precisions = _list_arg(args.precision, ["f32", "f64"], "precision", PRECISIONS)
    backends = _list_arg(args.backend, ["cpu"], "backend", ["cpu", "interp", "cuda"])
    if args.dt:
        dts = [check_dt(float(x)) for x in _floats(args.dt)]
    elif args.dts < 1:
        raise SceneError(f"--dts must be >= 1, not {args.dts}")
    else:
        dts = sw.default_dts(cls.default_dt, args.dts)
    if not dts:
        raise SceneError("--dt lists no time step")
    t_end = args.t_end if args.t_end is not None else cls.default_dt * cls.default_steps
    t_end = check_dt(t_end)  # a finite time > 0, like a dt
    if args.plot:
        sw.require_matplotlib()  # before any work: say which extra to install
        if not Path(args.plot).parent.is_dir():
            raise SceneError(f"cannot write {args.plot}: no directory {Path(args.plot).parent}")
    if args.json and not Path(args.json).parent.is_dir():
        raise SceneError(f"cannot write {args.json}: no directory {Path(args.json).parent}")
    for b in backends:
        if b == "cuda" and "cuda" not in available_backends():
            raise SceneError(f"backend 'cuda' is not available here (available: "
                             f"{', '.join(available_backends())})")  # fmt: skip
    configs = [sw.Config(b, p, i) for b in backends for p in precisions for i in integrators]
    runs = len(configs) * len(dts)
    seconds, scenes = sw.estimate(args.name, configs, dts, t_end, _params(args.param))
    print(f"sweep {args.name}: {runs} runs ({len(configs)} configurations x {len(dts)} dts) "
          f"to t={t_end:g}; estimated {seconds:.1f} s")  # fmt: skip
    if seconds > args.max_seconds and not args.yes:
        raise SceneError(f"the sweep would take about {seconds:.0f} s (over --max-seconds "
                         f"{args.max_seconds:g}); pass --yes to run it, or fewer dts, "
                         f"integrators or precisions")  # fmt: skip
    bar = sw.progress(runs)
    try:
        results = sw.sweep(scenes, dts, t_end, bar.set_description, bar.update)
    finally:
        bar.close()
    print(f"{'integrator':18s}{'prec':6s}{'backend':8s}{'dt':>10s}{'steps':>7s}{'run s':>10s}"
          f"{'us/step':>10s}{'error':>11s}")  # fmt: skip
    for r in results:
        err = f"{r.error:.3e}" if math.isfinite(r.error) else "blow-up"
        print(f"{r.integrator:18s}{r.precision:6s}{r.backend:8s}{r.dt:>10.3g}{r.steps:>7d}"
              f"{r.wall_s:>10.4f}{r.step_us:>10.1f}{err:>11s}")  # fmt: skip
    print(f"(error: {results[0].error_what}; 'blow-up': the state went non-finite)")
    if args.json:
        write_json(args.json, {"scene": args.name, "t_end": t_end, "dts": dts,
                               "estimate_s": seconds, "runs": [r.as_dict() for r in results]})  # fmt: skip
    if args.plot:
        params = ", ".join(f"{k}={v}" for k, v in _params(args.param).items())
        sw.plot(results, args.plot, f"{args.name}: error against run time to t={t_end:g}"
                + (f" ({params})" if params else ""))  # fmt: skip
        print(f"plot: {args.plot}")
    return 0


def _floats(text: str) -> list[str]:
    return [x for x in text.split(",") if x.strip()]


def cmd_extremes(args: argparse.Namespace) -> int:
    """``kdsl scene extremes``: the scene's stiff and extreme cases, per precision."""
    from kdsl.scenes.extremes import run_extremes

    scene_class(args.name)
    precisions = _list_arg(args.precision, ["f16", "f32", "f64"], "precision", PRECISIONS)
    results = run_extremes(args.name, precisions, args.backend)
    print(f"scene {args.name}: extreme cases (error against the float64 reference)")
    width = max(len(r.case) for r in results) + 2
    print(f"{'case':{width}s}{'integrator':18s}{'prec':6s}{'dt':>9s}{'error':>11s}  notes")
    for r in results:
        err = "-" if r.error is None else f"{r.error:.3e}"
        notes = r.blowup or ", ".join(f"{k} {v:.2e}" for k, v in r.extra.items())
        print(f"{r.case:{width}s}{r.integrator:18s}{r.precision:6s}{r.dt:>9.3g}{err:>11s}  {notes}")
    if args.json:
        write_json(args.json, [r.as_dict() for r in results])
    return 0


def add_scene_parser(sub: Any) -> None:
    """Add ``scene`` and its subcommands to the ``kdsl`` parser's subparsers ``sub``."""
    p = sub.add_parser("scene", help="run, measure and inspect simulation scenes")
    ssub = p.add_subparsers(dest="scene_command", required=True, metavar="SUBCOMMAND")
    q = ssub.add_parser("list", help="the scenes, their integrators and parameters")
    q.set_defaults(run=cmd_list)
    for name, fn, help_ in (
        ("run", cmd_run, "error against run time for one configuration"),
        ("stability", cmd_stability, "largest stable dt per integrator and precision"),
        ("info", cmd_info, "what each kernel compiled: ops, features, adjoint, size, time"),
    ):
        q = ssub.add_parser(name, help=help_)
        q.add_argument("name", metavar="NAME", help="a scene (see `kdsl scene list`)")
        q.add_argument("--backend", default="cpu", help="cpu (default), cuda or interp")
        q.add_argument("--dt", type=float, help="time step (default: the scene's)")
        q.add_argument("--param", action="append", metavar="NAME=VALUE",
                       help="a scene parameter (repeatable)")  # fmt: skip
        q.add_argument("--json", metavar="OUT.json", help="also write the results as JSON")
        if name == "stability":
            q.add_argument("--integrator", help="comma-separated (default: all of the scene's)")
            q.add_argument("--precision", help="comma-separated (default: f16,f32,f64)")
            q.add_argument("--horizon", type=int, default=2000, help="steps per trial")
            q.add_argument("--drift-steps", type=int, default=10_000,
                           help="steps of the energy drift run")  # fmt: skip
        else:
            q.add_argument("--integrator", help="integrator name (default: the scene's first)")
            q.add_argument("--precision", default="f32", help="f16, f32 (default) or f64")
        if name == "run":
            q.add_argument("--steps", type=int, help="steps (default: the scene's)")
            q.add_argument("--render", metavar="OUT.gif|OUT.png", help="draw the run: an "
                           "animated GIF, or a PNG of the last frame (needs Pillow: the "
                           "scenes extra)")  # fmt: skip
            q.add_argument("--usd", metavar="OUT.usda", help="write the run as a USD "
                           "animation (needs usd-core: the usd extra)")  # fmt: skip
            q.add_argument("--frames", type=int, default=40,
                           help="frames recorded for --render/--usd (default 40)")  # fmt: skip
        q.set_defaults(run=fn)
    q = ssub.add_parser("sweep", help="error against run time over dt x precision x "
                        "integrator x backend, with a work-precision plot")  # fmt: skip
    q.add_argument("name", metavar="NAME", help="a scene (see `kdsl scene list`)")
    q.add_argument("--backend", help="comma-separated (default: cpu)")
    q.add_argument("--integrator", help="comma-separated (default: all of the scene's)")
    q.add_argument("--precision", help="comma-separated (default: f32,f64)")
    q.add_argument("--dt", help="comma-separated time steps (default: --dts halvings of "
                   "the scene's dt)")  # fmt: skip
    q.add_argument("--dts", type=int, default=4, help="how many halvings (default 4)")
    q.add_argument("--t-end", type=float, help="every run's end time (default: the "
                   "scene's dt x steps)")  # fmt: skip
    q.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="a scene parameter (repeatable)")  # fmt: skip
    q.add_argument("--json", metavar="OUT.json", help="write every run as JSON")
    q.add_argument("--plot", metavar="OUT.png", help="write the work-precision plot "
                   "(needs matplotlib: the scenes extra)")  # fmt: skip
    q.add_argument("--max-seconds", type=float, default=120.0,
                   help="estimated time above which --yes is required (default 120)")  # fmt: skip
    q.add_argument("--yes", action="store_true", help="run even above --max-seconds")
    q.set_defaults(run=cmd_sweep)
    q = ssub.add_parser("extremes", help="stiff and extreme cases per precision, blow-ups named")
    q.add_argument("name", metavar="NAME", help="a scene (see `kdsl scene list`)")
    q.add_argument("--backend", default="cpu", help="cpu (default), cuda or interp")
    q.add_argument("--precision", help="comma-separated (default: f16,f32,f64)")
    q.add_argument("--json", metavar="OUT.json", help="also write the results as JSON")
    q.set_defaults(run=cmd_extremes)
