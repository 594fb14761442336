"""The memory of a fit, known before anything large is allocated: :func:`estimate_fit_bytes` (a deliberately high
bound), :func:`minimum_fit_bytes` (what a fit needs at the least), :func:`plan_chunk` (the evaluation's block of
starts within ``GPFitConfig.max_batch_bytes``, or :class:`FitMemoryError`) and :func:`largest_fit_n` (the most
training points within a limit)."""

from __future__ import annotations

import math
import os
from typing import Callable

from cascgp.gp.config import GPFitConfig

__all__ = ["estimate_fit_bytes", "minimum_fit_bytes", "plan_chunk", "largest_fit_n", "physical_memory_bytes",
           "FitMemoryError"]

#: Cache-sized chunks: the element-wise kernel work runs on (c, n, n) blocks of about this many bytes per tensor
#: (measured, 1 thread: one (60, 500, 500) batch per op was 2.2x slower per evaluation than member-sized blocks, the
#: whole batch being memory-bandwidth bound; at n = 300 and 500 one member per block was 6 % faster than 5).
CACHE_CHUNK_BYTES = 1 << 20


class FitMemoryError(ValueError):
    """A fit refused before any large allocation: even one start at a time, its estimate is over
    ``GPFitConfig.max_batch_bytes``, or its least need is over the machine's physical memory (``machine``). Its
    message names ``max_batch_bytes``; ``need`` and ``limit`` (bytes), ``n`` and ``max_n`` (the most training points
    within ``limit``) say what fits."""

    def __init__(self, message: str, need: int = 0, limit: int = 0, n: int = 0, max_n: int = 0,
                 machine: bool = False) -> None:
        super().__init__(message)
        self.need, self.limit, self.n, self.max_n, self.machine = need, limit, n, max_n, machine

    def __reduce__(self) -> tuple:  # picklable with its fields (a worker's error crosses processes)
        return (type(self), (str(self), self.need, self.limit, self.n, self.max_n, self.machine))


def estimate_fit_bytes(n: int, d: int, n_gps: int, n_starts: int, chunk: int = 1) -> int:
    """Bytes :meth:`cascgp.gp.GPBank.fit` needs beyond the interpreter, before fitting (a deliberately high estimate).

    ``3 * chunk`` work matrices ``(n, n)`` of the batched evaluation (:func:`cascgp.gp.nll_and_grad`), the stored
    factor of every GP ``(n_gps, n, n)`` plus twelve ``(n, n)`` for the temporaries of the final factors and for
    allocator fragmentation (freed ``(n, n)`` blocks are not always returned to the system), the data copies
    (normalised inputs of every start, ``(n_gps * n_starts, n, d)``, twice), all float64, and 128 MiB of fixed
    overhead. Measured (``bench_cascgp --scaling``, 6 GPs x 10 starts, d = 18, two runs): peak RSS growth 40 / 68 /
    161-187 / 565-703 MiB at n = 250 / 500 / 1000 / 2000; a 3-GP fit at n = 4000 with one start grew by about
    835 MiB against this estimate's 2332 MiB.
    """
    return 8 * (3 * chunk * n * n + (n_gps + 12) * n * n + 2 * n_gps * n_starts * n * d + 6 * n_gps * n * d) \
        + (128 << 20)


def minimum_fit_bytes(n: int, d: int, n_gps: int, n_starts: int) -> int:
    """Bytes a fit needs at the least, one start at a time: three ``(n, n)`` work matrices, the stored factor of every
    GP and the data copies (:func:`estimate_fit_bytes` without its temporaries, margin and fixed overhead)."""
    return 8 * ((3 + n_gps) * n * n + 2 * n_gps * n_starts * n * d)


def largest_fit_n(limit: float, d: int, n_gps: int, n_starts: int,
                  need: Callable[[int, int, int, int], int] | None = None) -> int:
    """The most training points whose fit ``need`` (default: :func:`estimate_fit_bytes` with one start at a time)
    puts within ``limit`` bytes (0 if not even one); ``ValueError`` for a limit that is not finite."""
    if not math.isfinite(limit):
        raise ValueError(f"limit: expected a finite number of bytes, got {limit!r}")
    fn = need or (lambda n, d_, b, s: estimate_fit_bytes(n, d_, b, s, 1))
    lo, hi = 0, 1
    while fn(hi, d, n_gps, n_starts) <= limit:
        lo, hi = hi, 2 * hi
    while hi - lo > 1:  # need(lo) <= limit < need(hi)
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fn(mid, d, n_gps, n_starts) <= limit else (lo, mid)
    return lo


def physical_memory_bytes() -> int | None:
    """The machine's physical memory in bytes (``os.sysconf``), or ``None`` where the system does not say. In a
    container this is the host's memory, not the container's limit."""
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
    return pages * size if pages > 0 and size > 0 else None


def plan_chunk(cfg: GPFitConfig, n: int, d: int, n_gps: int) -> int:
    """Members per evaluation block: cache-sized, shrunk to keep :func:`estimate_fit_bytes` within
    ``cfg.max_batch_bytes``. :class:`FitMemoryError` (naming ``max_batch_bytes``) when even one member does not
    fit, or when a fit needs more than the machine's physical memory at the least (:func:`minimum_fit_bytes`: only
    fits that cannot run; a limit raised beyond the machine let them start, until the system killed them)."""
    chunk = max(1, CACHE_CHUNK_BYTES // (8 * n * n))
    need1 = estimate_fit_bytes(n, d, n_gps, cfg.n_restarts, 1)
    what = f"fitting {n_gps} GPs x {cfg.n_restarts} starts on n={n} points (d={d}) needs"
    if need1 > cfg.max_batch_bytes:
        max_n = largest_fit_n(cfg.max_batch_bytes, d, n_gps, cfg.n_restarts)
        # a GP needs 2 points: below that, fewer points cannot help (the fixed overhead alone can exceed the limit)
        advice = (f"at most n={max_n} points fit within it (memory grows as n^2): use fewer points, or raise "
                  "GPFitConfig.max_batch_bytes" if max_n >= 2 else
                  "not even 2 points fit within it: raise GPFitConfig.max_batch_bytes")
        raise FitMemoryError(
            f"max_batch_bytes: {what} about {need1 / 2**20:.0f} MiB even one start at a time (3 + {n_gps + 12} "
            f"matrices of {n}x{n} float64, the data and 128 MiB of fixed overhead), over GPFitConfig.max_batch_bytes "
            f"= {cfg.max_batch_bytes / 2**20:.0f} MiB; {advice}",
            need=need1, limit=cfg.max_batch_bytes, n=n, max_n=max_n, machine=False)
    machine = physical_memory_bytes()
    least = minimum_fit_bytes(n, d, n_gps, cfg.n_restarts)
    if machine is not None and least > machine:
        max_n = largest_fit_n(machine, d, n_gps, cfg.n_restarts, minimum_fit_bytes)
        raise FitMemoryError(
            f"max_batch_bytes: {what} at least {least / 2**20:.0f} MiB, more than this machine's "
            f"{machine / 2**20:.0f} MiB of memory (GPFitConfig.max_batch_bytes allows "
            f"{cfg.max_batch_bytes / 2**20:.0f} MiB); at most n={max_n} points could fit in it",
            need=least, limit=machine, n=n, max_n=max_n, machine=True)
    while chunk > 1 and estimate_fit_bytes(n, d, n_gps, cfg.n_restarts, chunk) > cfg.max_batch_bytes:
        chunk -= 1
    return chunk
