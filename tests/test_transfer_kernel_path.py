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
def test_every_job_is_keyed_with_the_kernel_path_it_runs_on(jit: str, monkeypatch) -> None:
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
    assert [job["compiled"] for job in seen] == ([True, True] if jit == "1" else [False, False])


@pytest.mark.parametrize("compiled", [False, None])
def test_a_job_runs_its_attempts_on_its_kernel_path(compiled: bool | None, monkeypatch) -> None:
    """``compiled=False``: the attempts run with the compiled loops off, whatever the worker has; ``None`` (callers
    that do not say, e.g. the studies) leaves the process's setting as it is."""
    import cascgp_experiments.transfer as transfer

    monkeypatch.setenv("CASCGP_JIT", "1")
    inside: list = []
    monkeypatch.setattr(transfer, "_controller_attempts",
                        lambda *args: inside.append(os.environ.get("CASCGP_JIT")) or [{"ok": True}])
    cfg = TransferConfig(controllers=("rbd",), tasks=("front",), attempts=1, revisit=False)
    assert transfer.controller_job(cfg.to_dict(), "rbd", None, compiled=compiled) == [{"ok": True}]
    assert inside == (["0"] if compiled is False else ["1"]) and os.environ["CASCGP_JIT"] == "1"


def test_a_resume_on_the_other_kernel_path_is_refused_naming_it(tmp_path, monkeypatch) -> None:
    from cascgp_experiments.transfer import claim_output

    cfg = TransferConfig(controllers=("rbd",), tasks=("front",), attempts=1, revisit=False)
    monkeypatch.setenv("CASCGP_JIT", "0")
    assert claim_output(cfg, tmp_path) == "new"
    (tmp_path / "buffers" / "rbd").mkdir(parents=True)
    (tmp_path / "buffers" / "rbd" / "episode.npz").write_bytes(b"x")
    assert claim_output(cfg, tmp_path) == "resume"
    settings = tmp_path / "cache" / "transfer" / "settings.json"
    import json

    flipped = {**json.loads(settings.read_text()), "compiled_kernels": True}  # as if run with the fast extra
    settings.write_text(json.dumps(flipped))
    with pytest.raises(ValueError, match=r"other settings \(it ran with the fast extra's compiled loops, this run "
                                         r"without; CASCGP_JIT=0 turns them off\)"):
        claim_output(cfg, tmp_path)
    assert json.loads(settings.read_text()) == flipped  # refused: nothing changed
