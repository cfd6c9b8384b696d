"""``kdsl scene sweep``: error against run time over dt x precision x integrator x backend.

Every run of a sweep ends at the same time ``t_end`` (``steps = round(t_end / dt)``),
so the errors are comparable and the work-precision plot (error against run time,
log-log, one line per integrator and precision) shows which configuration buys a
given accuracy cheapest. Before running, ``estimate`` times a few steps of each
configuration (which also compiles it) and adds the float64 references' cost; a
sweep estimated above the threshold needs ``--yes``.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kdsl.scenes.binding import SceneError
from kdsl.scenes.measure import RunResult, make_scene, run_scene

#: Steps timed per configuration by the estimate (after one compile step).
PROBE_STEPS = 3
#: The plotting extra, named in the error when matplotlib is missing.
PLOT_EXTRA = "pip install 'kdsl[scenes]'  (matplotlib)"


@dataclass(frozen=True)
class Config:
    """One line of the plot: backend, precision and integrator."""

    backend: str
    precision: str
    integrator: str


def default_dts(dt: float, count: int = 4) -> list[float]:
    """``count`` time steps halving from ``dt``."""
    return [dt / 2**i for i in range(count)]


def require_matplotlib() -> Any:
    """``matplotlib.pyplot`` on the Agg backend, or a ``SceneError`` naming the extra."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise SceneError(f"the work-precision plot needs matplotlib: {PLOT_EXTRA}") from None
    return plt


def estimate(name: str, configs: list[Config], dts: list[float], t_end: float,
             params: dict[str, Any]) -> tuple[float, dict[Config, Any]]:  # fmt: skip
    """Estimated seconds for the sweep, and the scene built per configuration (compiled)."""
    from kdsl.scenes.reference import reference_steps

    scenes: dict[Config, Any] = {}
    total = 0.0
    rk4_f64_step = None
    for c in configs:
        scene = scenes[c] = make_scene(name, c.precision, c.integrator, c.backend, **params)
        probe = run_scene_quiet(scene, dts[-1], PROBE_STEPS)
        step_s = probe.wall_s / PROBE_STEPS
        if c.precision == "f64" and c.integrator == "rk4":
            rk4_f64_step = step_s
        for dt in dts:
            total += max(1, round(t_end / dt)) * step_s
        scene.reset()
    any_scene = next(iter(scenes.values()))
    if hasattr(any_scene, "omega_max"):  # a small-step float64 reference, one per dt
        if rk4_f64_step is None:
            twin = make_scene(name, "f64", "rk4", configs[0].backend, **params)
            rk4_f64_step = run_scene_quiet(twin, dts[-1], PROBE_STEPS).wall_s / PROBE_STEPS
        total += sum(reference_steps(t_end, dt, any_scene.omega_max()) for dt in dts) * rk4_f64_step
    return total, scenes


def run_scene_quiet(scene: Any, dt: float, steps: int) -> RunResult:
    """``run_scene`` without the error (the probe needs only the time)."""
    return run_scene(scene, dt, steps, measure_error=False)


def progress(total: int) -> Any:
    """A progress bar over ``total`` runs: tqdm's if installed, else plain lines on stderr."""
    try:
        from tqdm import tqdm

        return tqdm(total=total, unit="run", file=sys.stderr, leave=False)
    except ImportError:
        return _PlainProgress(total)


class _PlainProgress:
    """What tqdm's bar does, as ``[i/n] label`` lines (no optional package needed)."""

    def __init__(self, total: int) -> None:
        self.total, self.done = total, 0

    def set_description(self, text: str) -> None:
        print(f"[{self.done + 1}/{self.total}] {text}", file=sys.stderr, flush=True)

    def update(self, n: int = 1) -> None:
        self.done += n

    def close(self) -> None:
        pass


def sweep(scenes: dict[Config, Any], dts: list[float], t_end: float,
          on_run: Callable[[str], None] | None = None,
          done: Callable[[], None] | None = None) -> list[RunResult]:  # fmt: skip
    """Run every configuration at every dt to ``t_end``; a blown-up run reports ``inf``."""
    results = []
    for c, scene in scenes.items():
        for dt in dts:
            if on_run:
                on_run(f"{c.integrator} {c.precision} {c.backend} dt={dt:g}")
            scene.reset()
            r = run_scene(scene, dt, max(1, round(t_end / dt)), c.backend)
            if not math.isfinite(r.error):
                r.error = math.inf
            results.append(r)
            if done:
                done()
    return results


def plot(results: list[RunResult], path: str, title: str) -> None:
    """The work-precision plot (error against run time, log-log) to ``path``, atomically."""
    plt = require_matplotlib()
    target = Path(path)
    if not target.parent.is_dir():
        raise SceneError(f"cannot write {path}: no directory {target.parent}")
    lines: dict[tuple[str, str, str], list[RunResult]] = {}
    for r in results:
        lines.setdefault((r.integrator, r.precision, r.backend), []).append(r)
    backends = {r.backend for r in results}
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=80)
    styles = {"f16": ":", "f32": "--", "f64": "-"}
    # One colour per integrator, one line style per precision.
    colours = {i: f"C{n}" for n, i in enumerate(dict.fromkeys(r.integrator for r in results))}
    for (integ, prec, backend), rs in sorted(lines.items()):
        ok = [r for r in rs if math.isfinite(r.error) and r.error > 0]
        if not ok:
            continue
        label = f"{integ} {prec}" + (f" {backend}" if len(backends) > 1 else "")
        ax.loglog([r.wall_s for r in ok], [r.error for r in ok], styles.get(prec, "-"),
                  color=colours[integ], marker="o", markersize=3, label=label)  # fmt: skip
    ax.set_xlabel("run time (s)")
    ax.set_ylabel(results[0].error_what if results else "error", fontsize=7)
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".png", dir=target.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, format="png")
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would outlive the rename
        os.replace(tmp, target)
    except BaseException:
        os.unlink(tmp)
        raise
    finally:
        plt.close(fig)
