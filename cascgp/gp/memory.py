"""The memory of a fit, known before anything large is allocated: :func:`estimate_fit_bytes` (a deliberately high
bound), :func:`plan_chunk` (the evaluation's block of starts within ``GPFitConfig.max_batch_bytes`` and the machine's
memory, or :class:`FitMemoryError`) and :func:`largest_fit_n` (the most training points within a limit)."""

from __future__ import annotations

import os

from cascgp.gp.config import GPFitConfig

__all__ = ["estimate_fit_bytes", "plan_chunk", "largest_fit_n", "physical_memory_bytes", "FitMemoryError"]

#: Cache-sized chunks: the element-wise kernel work runs on (c, n, n) blocks of about this many bytes per tensor
#: (measured, 1 thread: one (60, 500, 500) batch per op was 2.2x slower per evaluation than member-sized blocks, the
#: whole batch being memory-bandwidth bound; at n = 300 and 500 one member per block was 6 % faster than 5).
CACHE_CHUNK_BYTES = 1 << 20


class FitMemoryError(ValueError):
    """A fit that would need more memory than ``GPFitConfig.max_batch_bytes`` allows, or than the machine has,
    even one start at a time; refused before any large allocation. Its message names ``max_batch_bytes``;
    ``need``, ``limit`` (bytes), ``n`` and ``max_n`` (the most training points within ``limit``) say what fits,
    and ``machine`` is set when the limit is the machine's memory rather than ``max_batch_bytes``."""

    def __init__(self, message: str, need: int, limit: int, n: int, max_n: int, machine: bool) -> None:
        super().__init__(message)
        self.need, self.limit, self.n, self.max_n, self.machine = need, limit, n, max_n, machine


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


def largest_fit_n(limit: int, d: int, n_gps: int, n_starts: int) -> int:
    """The most training points whose fit :func:`estimate_fit_bytes` (one start at a time) puts within ``limit``
    bytes (0 if not even one)."""
    lo, hi = 0, 1
    while estimate_fit_bytes(hi, d, n_gps, n_starts, 1) <= limit:
        lo, hi = hi, 2 * hi
    while hi - lo > 1:  # estimate(lo) <= limit < estimate(hi)
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if estimate_fit_bytes(mid, d, n_gps, n_starts, 1) <= limit else (lo, mid)
    return lo


def physical_memory_bytes() -> int | None:
    """The machine's physical memory in bytes (``os.sysconf``), or ``None`` where the system does not say."""
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
    return pages * size if pages > 0 and size > 0 else None


def plan_chunk(cfg: GPFitConfig, n: int, d: int, n_gps: int) -> int:
    """Members per evaluation block: cache-sized, shrunk to keep :func:`estimate_fit_bytes` within
    ``cfg.max_batch_bytes`` and the machine's physical memory; :class:`FitMemoryError` (naming ``max_batch_bytes``)
    when even one member does not fit."""
    chunk = max(1, CACHE_CHUNK_BYTES // (8 * n * n))
    need1 = estimate_fit_bytes(n, d, n_gps, cfg.n_restarts, 1)
    machine = physical_memory_bytes()
    by_machine = machine is not None and machine < cfg.max_batch_bytes
    limit = machine if machine is not None and by_machine else cfg.max_batch_bytes
    if need1 > limit:
        max_n = largest_fit_n(limit, d, n_gps, cfg.n_restarts)
        over = (f"over this machine's {limit / 2**20:.0f} MiB of memory (GPFitConfig.max_batch_bytes allows "
                f"{cfg.max_batch_bytes / 2**20:.0f} MiB)" if by_machine else
                f"over GPFitConfig.max_batch_bytes = {cfg.max_batch_bytes / 2**20:.0f} MiB")
        raise FitMemoryError(
            f"max_batch_bytes: fitting {n_gps} GPs x {cfg.n_restarts} starts on n={n} points (d={d}) needs about "
            f"{need1 / 2**20:.0f} MiB even one start at a time (3 + {n_gps + 12} matrices of {n}x{n} float64, the "
            f"data and 128 MiB of fixed overhead), {over}; at most n={max_n} points fit within it (memory grows as "
            f"n^2){'' if by_machine else '; or raise GPFitConfig.max_batch_bytes'}",
            need=need1, limit=limit, n=n, max_n=max_n, machine=by_machine)
    while chunk > 1 and estimate_fit_bytes(n, d, n_gps, cfg.n_restarts, chunk) > limit:
        chunk -= 1
    return chunk
