"""The native thread pool: workers parked in native code, a launch handed over without Python.

The Python pool (``pool``) hands a launch to its workers through queues: every
worker has to wake up, take the GIL, read its task and call the kernel through
``ctypes``, then report back through another queue. Here the workers are threads
that enter native code once (``kdsl_pool_worker``, through ``ctypes``, which
releases the GIL) and never come back: they sleep on a futex until a launch bumps
the pool's generation counter, run their share of the range function through a
function pointer, and count down a second futex word that the launching thread
sleeps on. A launch is one ``ctypes`` call (``kdsl_pool_run``), which runs share 0
itself. Measured on the 2-core host under load (a no-op range function, two threads):
2.0 us back to back against 7.8 us for the Python pool, 6.6 us against 38.5 us after
the workers idled for 2 ms.

The runtime is LLVM IR (``source``), built like a kernel and kept in the kernel
cache as one (``CpuBackend.support``, loaded by the compile driver), so a warm start
loads it without llvmlite. Linux only (futexes), x86-64 and AArch64 (the futex
system call's number); elsewhere the Python pool runs every launch.

A worker keeps polling a little after its share (``WORKER_SPIN`` rounds) before it
sleeps, and the launching thread a little while it waits (``LAUNCHER_SPIN``); each
round yields the core (``sched_yield``). Measured on the 2-core VM: quiet, back-to-back
launches of a 64-thread kernel took 2.1 us per hand-off with the worker polling (with
``pause`` instead of a yield), against 3.2 us or, in about half the runs, 65 us without
(an idle vCPU that sleeps takes tens of microseconds to wake); the Python pool took 65
to 75 us. Under load (load average 7 on 2 cores), polling with ``pause`` made the
100-kernel graph row 7x slower (7.07 ms launched against 1.02 ms without polling: the
polling worker took the core the launching thread needed), yielding did not (0.97 ms).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import sys
import threading
from typing import Any

#: ``sched_yield`` calls a worker makes, after its share of a launch, before sleeping
#: (well under a millisecond): launches that follow each other find it awake, and on a
#: loaded host it gives its core away at each one.
WORKER_SPIN = 200
#: ``sched_yield`` calls the launching thread makes, after its share, before sleeping.
LAUNCHER_SPIN = 20

_FUTEX_SYSCALL = {"x86_64": 202, "amd64": 202, "aarch64": 98, "arm64": 98}

# The pool's memory (bytes): 0 generation (i32 futex word) | 64 pending (i32 futex word) |
# 128 function | 136 total | 144 args | 152 dims | 160 chunks | 168 stop | 176 sleepers
# (i32) | 192 launcher waiting (i32) | 200 worker spin | 208 launcher spin. The two futex
# words sit on their own cache lines.
POOL_BYTES = 256

#: Byte offsets of the pool's fields (see the layout above), as the IR names them.
_FIELDS = {
    "genp": 0, "pendp": 64, "fnp": 128, "totp": 136, "argp": 144, "dimp": 152, "ncp": 160,
    "stopp": 168, "sleepp": 176, "waitp": 192, "wspinp": 200, "lspinp": 208,
}  # fmt: skip

_IR = """
declare i64 @syscall(i64, ...)
declare i32 @sched_yield()

define internal void @futex_wait(ptr %addr, i32 %val) {
  call i64 (i64, ...) @syscall(i64 @FUTEX@, ptr %addr, i32 128, i32 %val, ptr null)
  ret void
}

define internal void @futex_wake(ptr %addr, i32 %n) {
  call i64 (i64, ...) @syscall(i64 @FUTEX@, ptr %addr, i32 129, i32 %n)
  ret void
}

; Returns once *word != value: yields the core up to *spinp times, then sleeps on the
; futex.
; Announces a sleep in *sleepers, then looks again: whoever changes the word does so
; before reading the sleepers (both sequentially consistent), so one of the two sees
; the other and no wake-up is lost.
define internal void @wait_while_equal(ptr %word, i32 %value, ptr %sleepers, ptr %spinp) {
entry:
  %spin = load atomic i64, ptr %spinp monotonic, align 8
  br label %check
check:
  %i = phi i64 [0, %entry], [%i1, %yield], [0, %woke]
  %now = load atomic i32, ptr %word acquire, align 4
  %changed = icmp ne i32 %now, %value
  br i1 %changed, label %done, label %more
more:
  %i1 = add i64 %i, 1
  %keep = icmp slt i64 %i, %spin
  br i1 %keep, label %yield, label %sleep
yield:
  call i32 @sched_yield()
  br label %check
sleep:
  atomicrmw add ptr %sleepers, i32 1 seq_cst
  %again = load atomic i32, ptr %word seq_cst, align 4
  %same = icmp eq i32 %again, %value
  br i1 %same, label %dosleep, label %woke
dosleep:
  call void @futex_wait(ptr %word, i32 %value)
  br label %woke
woke:
  atomicrmw sub ptr %sleepers, i32 1 seq_cst
  br label %check
done:
  ret void
}

; Wakes up to %n threads sleeping on *word, if *sleepers says any are: called right
; after changing *word (the other half of wait_while_equal's handshake).
define internal void @wake_sleepers(ptr %word, ptr %sleepers, i32 %n) {
entry:
  %s = load atomic i32, ptr %sleepers seq_cst, align 4
  %any = icmp ne i32 %s, 0
  br i1 %any, label %wake, label %done
wake:
  call void @futex_wake(ptr %word, i32 %n)
  br label %done
done:
  ret void
}

define void @kdsl_pool_worker_@TAG@(ptr %pool, i64 %index) {
entry:
@FIELDS@
  br label %loop
loop:
  ; Fresh pool memory starts at generation 0. Not a load at entry: the first launch may
  ; bump the generation before this thread gets here, and must not be missed.
  %seen = phi i32 [0, %entry], [%g, %got], [%g, %run], [%g, %last]
  call void @wait_while_equal(ptr %genp, i32 %seen, ptr %sleepp, ptr %wspinp)
  br label %got0
got0:
  %g = load atomic i32, ptr %genp acquire, align 4
  %stop = load atomic i64, ptr %stopp acquire, align 8
  %isstop = icmp ne i64 %stop, 0
  br i1 %isstop, label %exit, label %got
got:
  %n = load i64, ptr %ncp
  %k = add i64 %index, 1
  %mine = icmp slt i64 %k, %n
  br i1 %mine, label %run, label %loop
run:
  %fn = load ptr, ptr %fnp
  %total = load i64, ptr %totp
  %args = load ptr, ptr %argp
  %dims = load ptr, ptr %dimp
  %a = mul i64 %total, %k
  %start = sdiv i64 %a, %n
  %k1 = add i64 %k, 1
  %b = mul i64 %total, %k1
  %end = sdiv i64 %b, %n
  call void %fn(i64 %start, i64 %end, ptr %args, ptr %dims)
  %old = atomicrmw sub ptr %pendp, i32 1 seq_cst
  %islast = icmp eq i32 %old, 1
  br i1 %islast, label %last, label %loop
last:
  call void @wake_sleepers(ptr %pendp, ptr %waitp, i32 1)
  br label %loop
exit:
  ret void
}

define void @kdsl_pool_run_@TAG@(ptr %pool, ptr %fn, i64 %total, ptr %args, ptr %dims, i64 %n) {
entry:
@FIELDS@
  store ptr %fn, ptr %fnp
  store i64 %total, ptr %totp
  store ptr %args, ptr %argp
  store ptr %dims, ptr %dimp
  store i64 %n, ptr %ncp
  %nm1 = sub i64 %n, 1
  %p32 = trunc i64 %nm1 to i32
  store atomic i32 %p32, ptr %pendp release, align 4
  atomicrmw add ptr %genp, i32 1 seq_cst
  call void @wake_sleepers(ptr %genp, ptr %sleepp, i32 2147483647)
  %end0 = sdiv i64 %total, %n
  call void %fn(i64 0, i64 %end0, ptr %args, ptr %dims)
  br label %wait
wait:
  %p = load atomic i32, ptr %pendp acquire, align 4
  %done = icmp eq i32 %p, 0
  br i1 %done, label %exit, label %sleep
sleep:
  call void @wait_while_equal(ptr %pendp, i32 %p, ptr %waitp, ptr %lspinp)
  br label %wait
exit:
  ret void
}

; A whole launch on the calling thread from one record {fn, total, args, dims}: a
; ctypes call with one argument costs half one with four.
define void @kdsl_pool_call_@TAG@(ptr %rec) {
entry:
  %fn = load ptr, ptr %rec
  %tp = getelementptr i8, ptr %rec, i64 8
  %total = load i64, ptr %tp
  %ap = getelementptr i8, ptr %rec, i64 16
  %args = load ptr, ptr %ap
  %dp = getelementptr i8, ptr %rec, i64 24
  %dims = load ptr, ptr %dp
  call void %fn(i64 0, i64 %total, ptr %args, ptr %dims)
  ret void
}

define void @kdsl_pool_noop_@TAG@(i64 %s, i64 %e, ptr %a, ptr %d) {
  ret void
}
"""


def _machine() -> str:
    return os.uname().machine if hasattr(os, "uname") else ""


def source() -> str | None:
    """The runtime's LLVM IR for this host, or None where there is no native pool."""
    machine = _machine()
    if not sys.platform.startswith("linux") or machine not in _FUTEX_SYSCALL:
        return None
    text = _IR.replace("@FUTEX@", str(_FUTEX_SYSCALL[machine]))
    fields = "\n".join(
        f"  %{name} = getelementptr i8, ptr %pool, i64 {offset}" for name, offset in _FIELDS.items()
    )
    text = text.replace("@FIELDS@", fields)
    # Symbols named after the text: two versions of the runtime never clash in the JIT.
    tag = hashlib.sha256(text.encode()).hexdigest()[:12]
    return text.replace("@TAG@", tag)


def symbols(text: str) -> dict[str, str]:
    """The runtime's entry points in ``text``: role -> symbol."""
    tag = text.split("@kdsl_pool_noop_", 1)[1].split("(", 1)[0]
    return {role: f"kdsl_pool_{role}_{tag}" for role in ("worker", "run", "noop", "call")}


_WORKER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int64)
_RUN = ctypes.CFUNCTYPE(None, *([ctypes.c_void_p] * 6))
_CALL = ctypes.CFUNCTYPE(None, ctypes.c_void_p)


def record(fn: int, total: int, args: int, dims: int) -> Any:
    """The four-word launch record ``NativePool.call`` reads (keep it alive while used)."""
    return (ctypes.c_void_p * 4)(fn, total, args, dims)


@functools.cache
def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None)


def _allocate() -> int:
    """Zeroed pool memory from the C heap, aligned to a cache line.

    Not a Python object: daemon workers may still read it while the interpreter shuts
    down and frees its objects, so it is freed only after its workers have left.
    """
    calloc = _libc().calloc
    calloc.restype = ctypes.c_void_p
    raw = calloc(1, POOL_BYTES + 64)
    if not raw:
        raise MemoryError("cannot allocate the native pool's memory")
    aligned = (raw + 63) // 64 * 64
    _RAW[aligned] = raw
    return aligned


def _free(address: int) -> None:
    free = _libc().free
    free.argtypes = [ctypes.c_void_p]
    free(_RAW.pop(address))


#: Aligned pool memory -> the pointer calloc gave (for free).
_RAW: dict[int, int] = {}


class NativePool:
    """Worker threads parked in ``kdsl_pool_worker``; ``run`` hands them a launch."""

    def __init__(self, addresses: dict[str, int]) -> None:
        self._worker = _WORKER(addresses["worker"])
        self._run = _RUN(addresses["run"])
        #: A native range function doing nothing (what ``pool.dispatch_seconds`` times).
        self.noop = addresses["noop"]
        #: ``call(record)`` runs ``fn(0, total, args, dims)`` from a record of those four
        #: words on the calling thread (``record``).
        self.call = _CALL(addresses["call"])
        #: The address of the pool's memory (None: no workers yet).
        self._memory: int | None = None
        self._threads: list[threading.Thread] = []
        #: Held while a launch runs: a second launching thread runs inline instead.
        self.busy = threading.Lock()

    def _start(self, workers: int) -> int:
        """The pool's memory, with ``workers`` parked workers (started on first use)."""
        if self._memory is None or len(self._threads) != workers:
            self._stop_workers()
            address = self._memory = _allocate()
            words = (ctypes.c_int64 * (POOL_BYTES // 8)).from_address(address)
            words[_FIELDS["wspinp"] // 8] = WORKER_SPIN
            words[_FIELDS["lspinp"] // 8] = LAUNCHER_SPIN
            self._threads = [
                threading.Thread(
                    target=self._worker, args=(address, i), daemon=True, name=f"kdsl-native-{i}"
                )
                for i in range(workers)
            ]
            for t in self._threads:
                t.start()
        return self._memory

    def run(self, fn: int, total: int, args: int, dims: int, threads: int) -> bool:
        """Run range function ``fn`` over ``[0, total)`` in ``threads`` chunks (the calling
        thread takes the first); False, having run nothing, when another launch holds it."""
        if not self.busy.acquire(blocking=False):
            return False
        try:
            memory = self._start(threads - 1)
            self._run(memory, fn, total, args, dims, threads)
        finally:
            self.busy.release()
        return True

    def stop(self) -> None:
        """Wake every worker with the stop flag set and wait for them to leave."""
        with self.busy:
            self._stop_workers()

    def _stop_workers(self) -> None:
        """``stop`` with ``busy`` held by the caller."""
        if self._memory is None:
            return
        memory, threads = self._memory, self._threads
        ctypes.c_int64.from_address(memory + _FIELDS["stopp"]).value = 1
        # A launch with no chunk for anyone: workers see the generation change and stop.
        self._run(memory, self.noop, 0, None, None, 1)
        for t in threads:
            t.join()
        _free(memory)  # no thread reads it any more
        self._memory, self._threads = None, []

    def forget_threads(self) -> None:
        """After ``fork``: the child has none of the workers; start afresh on next use."""
        self._memory, self._threads = None, []
        self.busy = threading.Lock()
