"""The task transfer runs each controller on the kernel path its job was keyed with: the compiled control tick
and online sample (the ``fast`` extra) agree with the NumPy path to round-off only, and a learning loop carries
that forward, so a cached result of one path is never reused for the other, and a worker runs the planned one."""

from __future__ import annotations

import os

import pytest

import cascgp_experiments.execution as execution
from cascgp.models.fastkernel import jit_enabled
from cascgp_experiments.transfer import TransferConfig, kernel_path, run_transfer


@pytest.mark.parametrize("before", [None, "1", "0"])
def test_the_numpy_path_is_set_for_the_block_and_restored(before: str | None, monkeypatch) -> None:
    if before is None:
        monkeypatch.delenv("CASCGP_JIT", raising=False)
    else:
        monkeypatch.setenv("CASCGP_JIT", before)
    with kernel_path(False):
        assert os.environ["CASCGP_JIT"] == "0" and not jit_enabled()
    assert os.environ.get("CASCGP_JIT") == before
    with pytest.raises(KeyError), kernel_path(False):  # restored after an error too
        raise KeyError("x")
    assert os.environ.get("CASCGP_JIT") == before


def test_a_job_keyed_compiled_refuses_a_worker_without_the_compiled_path(monkeypatch) -> None:
    monkeypatch.setenv("CASCGP_JIT", "0")  # as a worker without Numba
    with pytest.raises(RuntimeError, match=r"compiled control tick .*cascgp-jaco\[fast\].*CASCGP_JIT=0"):
        with kernel_path(True):
            pass


@pytest.mark.parametrize("jit", ["0", "1"])
def test_the_job_key_says_compiled_only_when_the_compiled_path_runs(jit: str, monkeypatch) -> None:
    monkeypatch.setenv("CASCGP_JIT", jit)
    if jit == "1" and not jit_enabled():
        pytest.skip("Numba is not installed (the fast extra)")
    seen: list[dict] = []

    class Planned(Exception):
        pass

    def fake_run_jobs(fn, jobs, **kw):
        seen.extend(jobs)
        raise Planned

    monkeypatch.setattr(execution, "run_jobs", fake_run_jobs)
    cfg = TransferConfig(controllers=("rbd", "sp-inward"), tasks=("front",), attempts=1, revisit=False)
    with pytest.raises(Planned):
        run_transfer(cfg, None, workers=1, show_progress=False)
    assert [job.get("compiled") for job in seen] == [True, True] if jit == "1" else [None, None]
    assert all("compiled" not in job for job in seen) == (jit == "0")  # NumPy-path keys as before
