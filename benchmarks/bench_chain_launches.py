"""Host time of the `chain` scene's launches on the cpu, made as its step makes them.

    python benchmarks/bench_chain_launches.py [--reps 7] [--loops 2000] [--json PATH]

The scene is built at ``bench_scenes.SIZES``'s size (2,048 masses, velocity Verlet) and
stepped a few times (compiles, learnt launches), then three loops are timed: the pair of
``spring_jvp`` launches of a step (``rhs`` on ``v`` then on ``vh``: eight arguments, four
float32 scalars made afresh at each launch, the damping 0.0), the pair of ``axpy``
launches (four arguments, one fresh scalar) and the whole step. Each figure is the
minimum over ``--reps`` repetitions of ``--loops`` calls, per launch (per step for the
step): the kernels themselves take about 0.6 us, the rest is the launch path. Run it
from an export of another commit (``PYTHONPATH``) to compare launch paths. Results go to
benchmarks/results/chain_launches.json.
"""

import time
from collections.abc import Callable
from pathlib import Path

from bench_scenes import SIZES
from suite import harness

RESULTS = Path(__file__).resolve().parent / "results" / "chain_launches.json"


def _min_us(fn: Callable[[], None], reps: int, loops: int, per: int) -> float:
    """The minimum over ``reps`` of ``loops`` calls of ``fn``, in us per ``per`` launches."""
    best = float("inf")
    for _ in range(reps):
        start = time.perf_counter()
        for _ in range(loops):
            fn()
        best = min(best, time.perf_counter() - start)
    return 1e6 * best / (loops * per)


def main() -> int:
    """Measure, print the table and write the JSON."""
    parser = harness.script_parser(__doc__, RESULTS, reps=7)
    parser.add_argument("--loops", type=int, default=2000)
    args = parser.parse_args()
    from kdsl.scenes.measure import make_scene

    integrator, params, dt, _ = SIZES["chain"]
    scene = make_scene("chain", "f32", integrator, "cpu", binding="kdsl", **params)
    for _ in range(5):
        scene.step(dt)
    axpy, acc, vh = scene.stepper.k.axpy, scene.array(), scene.array()

    def springs() -> None:
        scene.rhs(scene.x, scene.v, acc)
        scene.rhs(scene.x, vh, acc)

    def axpys() -> None:  # the stepper's ``_axpy``: a fresh scalar per launch
        scene.launch(axpy, scene.n, [vh, scene.v, scene.real(0.5 * dt), acc])
        scene.launch(axpy, scene.n, [scene.x, scene.x, scene.real(dt), vh])

    rows = [
        ("spring_jvp launch", _min_us(springs, args.reps, args.loops, 2)),
        ("axpy launch", _min_us(axpys, args.reps, args.loops, 2)),
        ("step (5 launches)", _min_us(lambda: scene.step(dt), args.reps, args.loops, 1)),
    ]
    print(f"{'what':20s}{'us':>9s}")
    for name, us in rows:
        print(f"{name:20s}{us:>9.2f}")
    result = {**harness.script_meta("bench_chain_launches.py"), "params": params,
              "integrator": integrator, "rows": [{"what": n, "us": us} for n, us in rows]}  # fmt: skip
    harness.save_json(result, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
