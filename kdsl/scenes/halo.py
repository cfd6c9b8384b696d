"""Halo exchangers for the strip scenes (``kdsl.scenes.strips``): who sends ghost rows.

An exchanger has a ``rank`` and a ``size`` (strip ``rank`` of ``size``) and four
operations, which every rank calls in the same order:

- ``exchange(first_row, last_row, top, bottom)``: send this strip's first row up and
  its last row down; fill ``top`` with the row above (rank - 1's last) and ``bottom``
  with the row below (rank + 1's first). The edge strips leave the missing side alone;
- ``reduce_max(value)`` and ``reduce_sum(value)``: a float combined over the ranks;
- ``gather(values)``: every rank's NumPy array, in rank order.

``SingleStrip`` is the whole grid in one strip (nothing to exchange). ``DeviceTeam``
runs the strips in one process, one thread and one kdsl device each (several GPUs,
or several strips on the CPU), with ``kdsl.copy`` between devices (peer to peer where
enabled) for the ghost rows. ``TorchHalo`` runs the exchange through
``torch.distributed`` point-to-point operations on torch views of the kdsl arrays (no
copies: gloo on the CPU, NCCL on GPUs); on a GPU make kdsl launch on torch's stream
(``kdsl.ScopedStream(kdsl.stream_from_torch(device))``) so the exchange and the kernels
are ordered on one stream.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from kdsl.scenes.binding import SceneError


class HaloError(SceneError):
    """A collective between strips failed: a rank died, stalled past the timeout, or broke."""


class HaloAborted(HaloError):
    """Raised in a ``DeviceTeam`` strip stopped because another strip failed or timed out."""


class SingleStrip:
    """The exchanger of an undivided grid: one strip, nothing to send."""

    rank, size = 0, 1

    def exchange(self, first_row: Any, last_row: Any, top: Any, bottom: Any) -> None:
        """Nothing to do: the only strip has no neighbours."""

    def reduce_max(self, value: float) -> float:
        """``value`` (one rank)."""
        return value

    def reduce_sum(self, value: float) -> float:
        """``value`` (one rank)."""
        return value

    def gather(self, values: np.ndarray) -> list[np.ndarray]:
        """``[values]`` (one rank)."""
        return [values]


class DeviceTeam:
    """Strips in one process: strip ``k`` on ``devices[k]``, each stepped by its own thread.

    ``run(work)`` calls ``work(halo)`` in one thread per strip, with that strip's
    exchanger (``halo.rank``, ``halo.device``), and returns the results in rank order.
    The threads meet at a barrier with a timeout (``timeout_s``): one that fails or
    stalls breaks the barrier, so the others stop too, and ``run`` raises the first error.
    """

    def __init__(self, devices: Sequence[Any], timeout_s: float = 120.0) -> None:
        if not devices:
            raise SceneError("a DeviceTeam needs at least one device")
        self.devices = list(devices)
        self.size = len(self.devices)
        self.timeout_s = timeout_s
        self._barrier = threading.Barrier(self.size, timeout=timeout_s)
        self._board: list[Any] = [None] * self.size  # what each strip shows the others

    def run(self, work: Callable[[TeamHalo], Any]) -> list[Any]:
        """``work(halo)`` on every strip at once; its results in rank order."""
        results: list[Any] = [None] * self.size
        errors: list[BaseException | None] = [None] * self.size

        def body(rank: int) -> None:
            try:
                results[rank] = work(TeamHalo(self, rank))
            except BaseException as e:  # reported below, after the other threads stop
                errors[rank] = e
                self._barrier.abort()

        threads = [threading.Thread(target=body, args=(r,), name=f"kdsl-strip-{r}", daemon=True)
                   for r in range(self.size)]  # fmt: skip
        for t in threads:
            t.start()
        for t in threads:
            t.join(self.timeout_s)
        if any(t.is_alive() for t in threads):
            self._barrier.abort()
            raise HaloError(f"a strip's thread did not finish within {self.timeout_s} s")
        first = next((e for e in errors if e is not None and not isinstance(e, HaloAborted)), None)
        first = first or next((e for e in errors if e is not None), None)
        self._barrier.reset()
        if first is not None:
            raise first
        return results

    def _meet(self) -> None:
        try:
            self._barrier.wait()
        except threading.BrokenBarrierError:
            raise HaloAborted("another strip failed or timed out; this one stops") from None

    def _publish(self, rank: int, value: Any) -> list[Any]:
        """Every strip's ``value``, once all have given one. The caller must ``_meet``
        before its next ``_publish`` (no strip may overwrite the board while others read)."""
        self._board[rank] = value
        self._meet()
        return list(self._board)

    def _share(self, rank: int, value: Any) -> list[Any]:
        """``_publish``, then wait until every strip has read the board."""
        shared = self._publish(rank, value)
        self._meet()
        return shared


class TeamHalo:
    """One strip's exchanger in a ``DeviceTeam`` (made by ``DeviceTeam.run``)."""

    def __init__(self, team: DeviceTeam, rank: int) -> None:
        self.team, self.rank, self.size = team, rank, team.size
        self.device = team.devices[rank]

    def exchange(self, first_row: Any, last_row: Any, top: Any, bottom: Any) -> None:
        """Copy the neighbours' boundary rows into ``top`` and ``bottom`` (``kdsl.copy``)."""
        import kdsl as wp

        # No host synchronization: a copy between devices waits for the work enqueued on
        # both devices' streams and makes both wait for it. The first barrier puts each
        # strip's kernels that write its rows before the copies that read them, the second
        # the copies before the next kernels that write them again (and every read of the
        # board before the next exchange writes it).
        rows = self.team._publish(self.rank, (first_row, last_row))
        if self.rank > 0:
            wp.copy(top, rows[self.rank - 1][1])
        if self.rank < self.size - 1:
            wp.copy(bottom, rows[self.rank + 1][0])
        self.team._meet()

    def reduce_max(self, value: float) -> float:
        """The largest ``value`` over the strips."""
        return max(self.team._share(self.rank, value))

    def reduce_sum(self, value: float) -> float:
        """The sum of ``value`` over the strips (added in rank order, so every strip agrees)."""
        return float(sum(self.team._share(self.rank, value)))

    def gather(self, values: np.ndarray) -> list[np.ndarray]:
        """Every strip's ``values``, in rank order."""
        return [np.asarray(v) for v in self.team._share(self.rank, values)]


def torch_distributed() -> Any:
    """``torch.distributed``, or a ``SceneError`` saying how to install PyTorch."""
    try:
        import torch.distributed
    except ImportError:
        raise SceneError(
            "distributed strips need PyTorch's torch.distributed (pip install kdsl[torch])"
        ) from None
    return torch.distributed


class TorchHalo:
    """Ghost rows and reductions through ``torch.distributed`` (an initialized process group).

    ``group`` is the process group (default: the world). The kdsl arrays handed to
    ``exchange`` must live on the device this rank's backend serves (the CPU for gloo,
    the rank's GPU for NCCL).
    """

    def __init__(self, group: Any = None) -> None:
        dist = torch_distributed()
        if not dist.is_available() or not dist.is_initialized():
            raise SceneError(
                "TorchHalo needs an initialized torch.distributed process group "
                "(torch.distributed.init_process_group, e.g. under torchrun)"
            )
        self._dist = dist
        self.group = group
        self.rank = dist.get_rank(group)
        self.size = dist.get_world_size(group)
        self._tensors: dict[tuple[int, int], tuple[Any, Any]] = {}

    def _tensor(self, a: Any) -> Any:
        """A torch view of kdsl array ``a``, made once per buffer (the exchange is hot)."""
        from kdsl.interop.torch import to_torch

        key = (a.ptr, a.shape[0])
        hit = self._tensors.get(key)
        if hit is None:  # the array is kept alive with its view, so its address stays its own
            hit = self._tensors[key] = (a, to_torch(a, requires_grad=False))
        return hit[1]

    def _peer(self, rank: int) -> int:
        """The global rank of group rank ``rank`` (torch's p2p calls take global ranks)."""
        if self.group is None:
            return rank
        return self._dist.get_global_rank(self.group, rank)

    def exchange(self, first_row: Any, last_row: Any, top: Any, bottom: Any) -> None:
        """Swap boundary rows with the neighbouring ranks (see the module docstring)."""
        dist, ops = self._dist, []
        if self.rank > 0:
            up = self._peer(self.rank - 1)
            ops.append(dist.P2POp(dist.irecv, self._tensor(top), up, self.group))
            ops.append(dist.P2POp(dist.isend, self._tensor(first_row), up, self.group))
        if self.rank < self.size - 1:
            down = self._peer(self.rank + 1)
            ops.append(dist.P2POp(dist.irecv, self._tensor(bottom), down, self.group))
            ops.append(dist.P2POp(dist.isend, self._tensor(last_row), down, self.group))
        if ops:
            with self._failing("exchanging ghost rows"):
                for work in dist.batch_isend_irecv(ops):
                    work.wait()

    @contextlib.contextmanager
    def _failing(self, what: str) -> Iterator[None]:
        """Turn torch's error for a dead or stalled peer into a ``HaloError`` saying so."""
        try:
            yield
        except (RuntimeError, ValueError) as e:  # gloo/NCCL errors, DistBackendError
            raise HaloError(
                f"rank {self.rank} of {self.size}: {what} failed (did another rank die or "
                f"stall past the process group's timeout?): {e}"
            ) from e

    def _reduce(self, value: float, op: Any) -> float:
        import torch

        t = torch.tensor([value], dtype=torch.float64, device=self._device())
        with self._failing("a reduction"):
            self._dist.all_reduce(t, op=op, group=self.group)
        return float(t.item())

    def _device(self) -> str:
        # NCCL reduces GPU tensors only; gloo CPU tensors.
        if self._dist.get_backend(self.group) == "nccl":
            import torch

            return f"cuda:{torch.cuda.current_device()}"
        return "cpu"

    def reduce_max(self, value: float) -> float:
        """The largest ``value`` over the ranks."""
        return self._reduce(value, self._dist.ReduceOp.MAX)

    def reduce_sum(self, value: float) -> float:
        """The sum of ``value`` over the ranks."""
        return self._reduce(value, self._dist.ReduceOp.SUM)

    def gather(self, values: np.ndarray) -> list[np.ndarray]:
        """Every rank's ``values`` (NumPy, any shapes), in rank order, on every rank."""
        out: list[Any] = [None] * self.size
        with self._failing("a gather"):
            self._dist.all_gather_object(out, np.asarray(values), group=self.group)
        return out
