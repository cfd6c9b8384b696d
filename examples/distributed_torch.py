"""kdsl kernels in a torch.distributed job: ghost cells, an all-reduce, and gradients across ranks.

    torchrun --nproc-per-node 2 examples/distributed_torch.py                 # gloo, CPU
    torchrun --nproc-per-node 2 examples/distributed_torch.py --device cuda   # NCCL, a GPU a rank
    python examples/distributed_torch.py                                      # one process

A line of ``--points`` values is cut into one piece per rank. Each rank keeps its
piece in a torch tensor and runs kdsl kernels on it through zero-copy views
(``kdsl.from_torch`` / ``kdsl.to_torch``) on its own device:

1. ``--iters`` smoothing steps ``u[i] += a (u[i-1] - 2 u[i] + u[i+1])`` (zero beyond
   the ends). Before each step a rank trades its end values with its neighbours
   (``torch.distributed`` point-to-point: its ghost cells);
2. the loss ``sum (u - target)^2`` of each piece, added over the ranks by
   ``all_reduce``;
3. the gradient of that global loss with respect to the starting values: each kdsl
   kernel is a ``torch.autograd.Function`` whose backward replays a ``kdsl.Tape``, and
   the ghost-cell exchange is one too, whose backward sends the ghost cells' gradients
   back to the ranks that own those cells. ``loss.backward()`` on every rank then
   gives each rank the gradient for its piece.

Rank 0 then runs the same computation on the whole line in one piece, the world of one
process, and checks that the distributed loss and gradient match it (float64; the
sums are added in another order, so to rounding). On GPUs kdsl launches on torch's
current stream, so kernels and NCCL transfers are ordered without host syncs.
"""

import argparse
import contextlib
import datetime
import itertools
import os
import sys

import numpy as np
import torch
import torch.distributed as dist

import kdsl as wp


@wp.kernel
def smooth(u: wp.array(dtype=wp.float64), a: wp.float64, out: wp.array(dtype=wp.float64)):
    # u holds the piece with one ghost cell at each end: out[i] is cell u[i + 1] smoothed.
    i = wp.tid()
    out[i] = u[i + 1] + a * (u[i] - wp.float64(2.0) * u[i + 1] + u[i + 2])


@wp.kernel
def squared_error(
    u: wp.array(dtype=wp.float64), target: wp.array(dtype=wp.float64),
    loss: wp.array(dtype=wp.float64),
):  # fmt: skip
    i = wp.tid()
    d = u[i] - target[i]
    wp.atomic_add(loss, 0, d * d)


class Neighbours:
    """This rank's place on the line: who is left and right of it (None at the ends)."""

    def __init__(self, rank: int, size: int) -> None:
        self.rank, self.size = rank, size
        self.left = rank - 1 if rank > 0 else None
        self.right = rank + 1 if rank < size - 1 else None

    def swap(self, to_left: torch.Tensor, to_right: torch.Tensor) -> tuple:
        """Send one value each way; receive the neighbours' (zeros where there is none)."""
        from_left, from_right = torch.zeros_like(to_left), torch.zeros_like(to_right)
        ops = []
        if self.left is not None:
            ops += [dist.P2POp(dist.isend, to_left, self.left),
                    dist.P2POp(dist.irecv, from_left, self.left)]  # fmt: skip
        if self.right is not None:
            ops += [dist.P2POp(dist.isend, to_right, self.right),
                    dist.P2POp(dist.irecv, from_right, self.right)]  # fmt: skip
        if ops:
            for work in dist.batch_isend_irecv(ops):
                work.wait()
        return from_left, from_right


class GhostCells(torch.autograd.Function):
    """``u`` with the neighbours' end values added at both ends (zeros at the line's ends).

    Backward is the transpose: the gradient of a ghost cell goes back to the rank that
    owns the cell and is added to that cell's gradient.
    """

    @staticmethod
    def forward(ctx, u, nb):
        ctx.nb = nb
        left, right = nb.swap(u[:1].contiguous(), u[-1:].contiguous())
        return torch.cat([left, u, right])

    @staticmethod
    def backward(ctx, grad):
        # My left ghost is my left neighbour's last cell: its gradient goes left.
        from_left, from_right = ctx.nb.swap(grad[:1].contiguous(), grad[-1:].contiguous())
        g = grad[1:-1].clone()
        g[:1] += from_left  # the gradient of my first cell seen as my left neighbour's ghost
        g[-1:] += from_right
        return g, None


class TapedKernel(torch.autograd.Function):
    """``out = kernel(x, *rest)``: one kdsl launch recorded on a ``kdsl.Tape``, differentiable
    in the tensor ``x`` (its backward replays the tape with the incoming gradient)."""

    @staticmethod
    def forward(ctx, x, kernel, dim, rest, out_len):
        # kdsl sees the tensor's memory; its gradient goes to a fresh tensor (not x.grad).
        wx = wp.from_torch(x.detach(), requires_grad=True, grad=torch.zeros_like(x))
        out = wp.zeros(out_len, dtype=wp.float64, device=wx.device, requires_grad=True)
        ctx.tape = wp.Tape()
        with ctx.tape:
            wp.launch(kernel, dim=dim, inputs=[wx, *rest], outputs=[out], device=wx.device)
        ctx.x, ctx.out = wx, out
        return wp.to_torch(out, requires_grad=False)

    @staticmethod
    def backward(ctx, grad):
        ctx.tape.backward(grads={ctx.out: wp.from_torch(grad.contiguous())})
        return wp.to_torch(ctx.x.grad, requires_grad=False), None, None, None, None


def smooth_step(padded: torch.Tensor, a: float) -> torch.Tensor:
    """One smoothing step of a piece given with its ghost cells (kdsl kernel ``smooth``)."""
    n = len(padded) - 2
    return TapedKernel.apply(padded, smooth, n, [a], n)


def squared_error_sum(u: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """``sum (u - target)^2`` as a one-element tensor (kdsl kernel ``squared_error``)."""
    return TapedKernel.apply(u, squared_error, len(u), [wp.from_torch(target)], 1)


def problem(points: int) -> tuple[np.ndarray, np.ndarray]:
    """The whole line's starting values and target (the same on every rank)."""
    rng = np.random.default_rng(19)
    x = np.linspace(0.0, 1.0, points)
    return rng.random(points), np.sin(3.0 * np.pi * x)


def run(nb: Neighbours, u0: np.ndarray, target: np.ndarray, iters: int, a: float,
        device: str) -> tuple[float, np.ndarray, float]:  # fmt: skip
    """This rank's piece: the global loss, the gradient for the piece, the global sum u^2."""
    u = torch.tensor(u0, dtype=torch.float64, device=device, requires_grad=True)
    t = torch.tensor(target, dtype=torch.float64, device=device)
    v = u
    for _ in range(iters):
        v = smooth_step(GhostCells.apply(v, nb), a)
    local = squared_error_sum(v, t)
    # The global loss is the sum of the pieces' losses: each rank's backward of its own
    # piece gives the gradient of the sum, since the ghost cells carry the cross terms.
    local.backward()
    total = local.detach().clone()
    energy = torch.sum(v.detach() ** 2).reshape(1)
    if nb.size > 1:
        dist.all_reduce(total)  # SUM
        dist.all_reduce(energy)
    return float(total.item()), u.grad.cpu().numpy(), float(energy.item())


def pieces(points: int, size: int) -> list[tuple[int, int]]:
    """The ``[first, end)`` of each rank's piece."""
    edges = [round(points * r / size) for r in range(size + 1)]
    return list(itertools.pairwise(edges))


def main(argv: list[str] | None = None) -> int:
    """Run on every rank; rank 0 checks against one process. Returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--points", type=int, default=1000)
    p.add_argument("--iters", type=int, default=10)
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    p.add_argument("--timeout", type=float, default=120.0, help="seconds for any collective")
    args = p.parse_args(argv)
    a = 0.25  # stable: a <= 1/2
    distributed = "RANK" in os.environ
    if args.device == "cuda":
        local = int(os.environ.get("LOCAL_RANK", 0))
        torch.cuda.set_device(local)
        device = f"cuda:{local}"
    else:
        device = "cpu"
    if distributed:
        timeout = datetime.timedelta(seconds=args.timeout)
        dist.init_process_group("nccl" if args.device == "cuda" else "gloo", timeout=timeout)
        rank, size = dist.get_rank(), dist.get_world_size()
    else:
        rank, size = 0, 1
    if size > args.points:
        raise SystemExit(f"{args.points} points cannot be cut into {size} pieces")
    u0, target = problem(args.points)
    first, end = pieces(args.points, size)[rank]
    on_gpu = device != "cpu"
    stream = wp.ScopedStream(wp.stream_from_torch(device)) if on_gpu else contextlib.nullcontext()
    with stream:
        loss, grad, energy = run(Neighbours(rank, size), u0[first:end], target[first:end],
                                 args.iters, a, device)  # fmt: skip
        grads = [None] * size
        if distributed:
            dist.all_gather_object(grads, grad)
        else:
            grads = [grad]
        ok = True
        if rank == 0:
            ref_loss, ref_grad, ref_energy = run(Neighbours(0, 1), u0, target, args.iters, a,
                                                 device)  # fmt: skip
            whole = np.concatenate(grads)
            err = float(np.max(np.abs(whole - ref_grad)) / np.max(np.abs(ref_grad)))
            # The one-process gradient itself, against a central difference along d. The
            # loss is quadratic in u0, so the difference has no truncation error: a large
            # step keeps the rounding of the loss (a sum of many terms) small.
            d = np.random.default_rng(7).standard_normal(args.points)
            eps = 1e-2
            up, down = (run(Neighbours(0, 1), u0 + s * eps * d, target, args.iters, a, device)[0]
                        for s in (1.0, -1.0))  # fmt: skip
            fd_err = abs((up - down) / (2 * eps) - ref_grad @ d) / abs(ref_grad @ d)
            ok = bool(np.isclose(loss, ref_loss, rtol=1e-12) and err < 1e-12 and fd_err < 1e-6
                      and np.isclose(energy, ref_energy, rtol=1e-12))  # fmt: skip
            print(f"ranks={size} device={args.device} loss={loss:.15g} (one process "
                  f"{ref_loss:.15g}) sum_u2={energy:.15g} gradient_rel_error={err:.3g} "
                  f"finite_difference_rel_error={fd_err:.3g} {'ok' if ok else 'MISMATCH'}",
                  flush=True)  # fmt: skip
    if distributed:
        dist.destroy_process_group()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
