"""The grid scenes (heat, wave) cut into row strips with ghost rows: one strip per rank or device.

The ``grid x grid`` interior points are split by rows into ``size`` strips of nearly
equal height (``strip_bounds``); a ``HeatStrip`` or ``WaveStrip`` owns strip ``rank``:
its state arrays hold only that strip's rows, and before each Laplacian it fetches the
row above and the row below (its ghost rows) through a halo exchanger
(``kdsl.scenes.halo``: torch.distributed between processes, or nothing for one strip).

The strip Laplacian adds the same neighbours in the same order as the whole-grid kernel
(up, down, left, right) and skips the same ones at the domain's edges (by the global row
index), and the integrators' kernels are element-wise, so the strips together compute
exactly what one device computes: bit for bit on the same backend and precision.
"""

# No ``from __future__ import annotations``: kernel annotations name closure variables.

import itertools
from functools import cache
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from kdsl.scenes.binding import SceneError
from kdsl.scenes.heat import Heat
from kdsl.scenes.wave import Wave


def strip_bounds(rows: int, parts: int) -> list[tuple[int, int]]:
    """The ``[first, end)`` rows of each of ``parts`` strips of ``rows`` rows (sizes differ
    by at most one)."""
    if parts < 1:
        raise SceneError(f"a grid is cut into at least 1 strip, not {parts}")
    if parts > rows:
        raise SceneError(
            f"a grid of {rows} rows cannot be cut into {parts} strips (one row each at least)"
        )
    edges = [rows * p // parts for p in range(parts + 1)]
    return list(itertools.pairwise(edges))


@cache
def make_strip_kernels(wp: ModuleType, real: Any) -> SimpleNamespace:
    """``strip_laplacian(u, top, bottom, row0, n, s, out)``: the 5-point Laplacian of a strip
    whose rows start at global row ``row0``, reading the ghost rows ``top`` and ``bottom``."""

    @wp.kernel(module="unique")
    def strip_laplacian(
        u: wp.array(dtype=real), top: wp.array(dtype=real), bottom: wp.array(dtype=real),
        row0: int, n: int, s: real, out: wp.array(dtype=real),
    ):  # fmt: skip
        i, j = wp.tid()
        rows = u.shape[0] // n
        gi = row0 + i
        c = u[i * n + j]
        total = real(-4.0) * c
        # The whole-grid kernel's order (up, down, left, right), so the sums round alike.
        if gi > 0:
            if i > 0:
                total += u[(i - 1) * n + j]
            else:
                total += top[j]
        if gi < n - 1:
            if i < rows - 1:
                total += u[(i + 1) * n + j]
            else:
                total += bottom[j]
        if j > 0:
            total += u[i * n + j - 1]
        if j < n - 1:
            total += u[i * n + j + 1]
        out[i * n + j] = s * total

    return SimpleNamespace(strip_laplacian=strip_laplacian)


class StripMixin:
    """Makes a ``GridScene`` own one row strip (see the module docstring).

    The initial state and the reference are computed for the strip's rows only
    (``GridScene.rows``), so no rank ever holds the whole grid.

    Construct with ``halo`` (a ``kdsl.scenes.halo`` exchanger: its ``rank`` and
    ``size`` pick the strip) before the scene's usual arguments. ``state()`` and
    ``error()`` are the strip's; ``global_state()`` and ``global_error()`` combine the
    strips through the exchanger (every rank must call them).
    """

    def __init__(self, wp: ModuleType, halo: Any, *args: Any, **kwargs: Any) -> None:
        self.halo = halo
        super().__init__(wp, *args, **kwargs)

    def setup(self) -> None:
        super().setup()
        n = self.grid_n
        self.row0, self.row1 = self.rows = strip_bounds(n, self.halo.size)[self.halo.rank]

    def make_kernels(self, wp: ModuleType, real: Any) -> SimpleNamespace:
        k = super().make_kernels(wp, real)
        strip = make_strip_kernels(wp, real)
        self.top = wp.zeros(self.grid_n, dtype=real, device=self.device)
        self.bottom = wp.zeros(self.grid_n, dtype=real, device=self.device)
        return SimpleNamespace(**vars(k), strip_laplacian=strip.strip_laplacian)

    def _lap(self, u: Any, s: float, out: Any) -> None:
        n, rows = self.grid_n, self.row1 - self.row0
        self.halo.exchange(u[:n], u[(rows - 1) * n :], self.top, self.bottom)
        inputs = [u, self.top, self.bottom, self.row0, n, self.real(s / self.h**2), out]
        self.launch(self.k.strip_laplacian, (rows, n), inputs)

    def energy(self, x: np.ndarray, v: np.ndarray | None) -> float | None:
        # A strip's share of a global energy would need its neighbours' rows: not defined.
        return None

    def global_state(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The whole grid's state, the strips gathered in order (on every rank)."""
        x, v = self.state()
        gx = np.concatenate(self.halo.gather(x))
        return gx, (None if v is None else np.concatenate(self.halo.gather(v)))

    def global_error(self) -> float:
        """``error()`` over the whole grid (the largest deviation over the largest value)."""
        x, _ = self.state()
        ref = self.reference(self.t)
        deviation = self.halo.reduce_max(float(np.max(np.abs(x - ref))))
        scale = self.halo.reduce_max(float(np.max(np.abs(ref))))
        return deviation / max(scale, 1e-300)


class HeatStrip(StripMixin, Heat):
    """One row strip of the ``heat`` scene (see ``StripMixin``)."""


class WaveStrip(StripMixin, Wave):
    """One row strip of the ``wave`` scene (see ``StripMixin``)."""


#: Scene name -> its strip class.
STRIP_SCENES = {"heat": HeatStrip, "wave": WaveStrip}


def strip_scene_class(name: str) -> Any:
    """The strip class of grid scene ``name`` (a ``SceneError`` naming the choices if none)."""
    if name not in STRIP_SCENES:
        raise SceneError(
            f"scene {name!r} has no domain-decomposed form (choices: {', '.join(STRIP_SCENES)})"
        )
    return STRIP_SCENES[name]
