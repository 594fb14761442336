"""A data buffer that persists across episodes and tasks.

Every appended record (one episode, typically) is written to its own ``.npz`` file
in the buffer's folder with :meth:`cascgp.data.DynamicsData.save`, which is atomic,
so an interrupted run never leaves a half-written buffer: reopening the folder
gives every episode that was completely saved.

No episode is ever overwritten: a new file takes the number after the highest one in
the folder *at the time of the append* (a gap left by a removed file is not filled; the number
of a removed *last* file is taken again, since nothing on disk remembers it),
and it is published exclusively (:func:`cascgp.io.atomic_write` with ``exclusive``), so
two buffers appending to one folder each keep all their episodes; one buffer does not
see the other's later episodes until the folder is reopened.

Training-set cap
----------------
:meth:`DataBuffer.training_set` subsamples all data to ``rate_hz`` (10 Hz by default,
as in the paper) and, if more than ``max_samples`` rows remain, keeps
``max_samples`` rows evenly spaced over the whole buffer (every episode keeps its
share, so older tasks are not forgotten). Exact GP training is O(n^3), so the cap
bounds the retraining time between tasks.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from cascgp.checks import check_count, check_positive
from cascgp.data import DynamicsData
from cascgp.io import file_in_path

_EPISODE_FILE = re.compile(r"^episode_(\d{5,})\.npz$")


class DataBuffer:
    """Episodes of measured robot data, optionally mirrored to a folder on disk.

    Args:
        folder: where episodes are saved (created if missing); ``None`` keeps the buffer
            in memory only. Opening an existing folder loads the episodes already in it.

    Example:
        >>> import numpy as np
        >>> from cascgp.data import DynamicsData
        >>> t = np.arange(0.0, 10.0, 0.01)                      # one 10 s episode at 100 Hz
        >>> q = np.sin(t)[:, None]
        >>> buffer = DataBuffer()                               # in memory; DataBuffer("runs/buffer") persists
        >>> buffer.append(DynamicsData(q=q, qd=q, qdd=q, tau=q, t=t))
        >>> buffer.training_set(rate_hz=10.0, max_samples=50).n_samples  # 10 Hz, thinned to 50 rows
        50
    """

    def __init__(self, folder: str | os.PathLike[str] | None = None) -> None:
        if folder is not None and not str(os.fspath(folder)).strip():
            raise ValueError("folder: expected a folder path (or None for a buffer in memory), got an empty path")
        self.folder = None if folder is None else Path(folder)
        self._episodes: list[DynamicsData] = []
        if self.folder is not None:
            try:
                self.folder.mkdir(parents=True, exist_ok=True)
            except (FileExistsError, NotADirectoryError):  # the folder, or a part of its path, is a file
                raise NotADirectoryError(f"folder: cannot keep the buffer's episodes in {self.folder}: "
                                         f"{file_in_path(self.folder)} is a file") from None
            found = [(int(m.group(1)), p) for p in self.folder.iterdir() if (m := _EPISODE_FILE.match(p.name))]
            paths = [p for _, p in sorted(found, key=lambda e: e[0])]
            self._episodes = [DynamicsData.load(p) for p in paths]
            for p, e in zip(paths, self._episodes):
                if e.dof != self._episodes[0].dof:
                    raise ValueError(f"folder: {p} holds {e.dof}-DOF data, {paths[0].name} {self._episodes[0].dof}-DOF "
                                     "data; one buffer holds one robot's episodes")

    def __len__(self) -> int:
        return len(self._episodes)

    @property
    def n_samples(self) -> int:
        """Total number of samples over all episodes."""
        return sum(e.n_samples for e in self._episodes)

    @property
    def episodes(self) -> tuple[DynamicsData, ...]:
        """The episodes held, oldest first."""
        return tuple(self._episodes)

    def append(self, data: DynamicsData) -> None:
        """Add one episode (saved to the folder at once, atomically, when there is one)."""
        if not isinstance(data, DynamicsData):
            raise TypeError(f"data must be a DynamicsData, got {type(data).__name__}")
        if self._episodes and data.dof != self._episodes[0].dof:
            raise ValueError(f"data.dof is {data.dof}, the buffer holds {self._episodes[0].dof}-DOF data")
        if self.folder is not None:
            while True:
                try:
                    data.save(self.folder / f"episode_{self._next_index():05d}.npz", exclusive=True)
                    break
                except FileExistsError:  # another writer took the number first: take the next one
                    continue
        self._episodes.append(data)

    def _next_index(self) -> int:
        """One past the highest episode number on disk (0 for an empty folder)."""
        assert self.folder is not None  # called only for a buffer kept in a folder
        nums = [int(m.group(1)) for p in self.folder.iterdir() if (m := _EPISODE_FILE.match(p.name))]
        return max(nums, default=-1) + 1

    def all_data(self) -> DynamicsData:
        """Every episode concatenated (each episode its own segment)."""
        if not self._episodes:
            raise ValueError("the buffer is empty")
        return DynamicsData.concat(self._episodes)

    def training_set(self, rate_hz: float = 10.0, max_samples: int = 500) -> DynamicsData:
        """All data subsampled to ``rate_hz`` and thinned evenly to at most ``max_samples`` rows."""
        rate_hz = check_positive(rate_hz, "rate_hz", "Hz")
        max_samples = check_count(max_samples, "max_samples", 2)
        data = DynamicsData.concat([e.subsample(rate_hz) for e in self._episodes]) if self._episodes else None
        if data is None:
            raise ValueError("the buffer is empty")
        return data.thin(max_samples)
