"""A fit sets torch's and BLAS's threads to GPFitConfig.threads while it runs and restores the caller's afterwards."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import torch

from cascgp.gp import GPBank, GPFitConfig


def _data(n: int = 30) -> tuple[list[np.ndarray], list[np.ndarray]]:
    rng = np.random.default_rng(0)
    X = rng.uniform(-1, 1, (n, 2))
    return [X], [np.sin(3 * X[:, 0]) + 0.01 * rng.standard_normal(n)]


@pytest.mark.parametrize("threads, expected", [(1, 1), (2, 2), (None, 3)])
def test_fit_runs_with_its_threads_and_restores_the_callers(monkeypatch, threads, expected) -> None:
    from threadpoolctl import threadpool_info

    seen: dict[str, object] = {}
    real_fit = GPBank._fit

    def spy(self, X, y, init, shared=None):
        seen["torch"] = torch.get_num_threads()
        seen["blas"] = {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}
        return real_fit(self, X, y, init, shared)

    monkeypatch.setattr(GPBank, "_fit", spy)
    before = torch.get_num_threads()
    torch.set_num_threads(3)
    try:
        GPBank(GPFitConfig(n_restarts=1, max_iter=5, threads=threads)).fit(*_data())
        assert seen["torch"] == expected
        if threads is not None:
            assert seen["blas"] <= {threads}
        assert torch.get_num_threads() == 3
    finally:
        torch.set_num_threads(before)


def test_threads_are_restored_when_the_fit_raises(monkeypatch) -> None:
    before = torch.get_num_threads()
    torch.set_num_threads(3)

    def boom(self, X, y, init, shared=None):
        raise RuntimeError("inside the fit")

    monkeypatch.setattr(GPBank, "_fit", boom)
    try:
        with pytest.raises(RuntimeError, match="inside the fit"):
            GPBank(GPFitConfig(threads=1)).fit(*_data())
        assert torch.get_num_threads() == 3
    finally:
        torch.set_num_threads(before)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_bad_thread_counts_are_refused(bad) -> None:
    with pytest.raises(ValueError, match="threads: expected None or an integer >= 1"):
        GPFitConfig(threads=bad)


def test_saved_configs_without_the_field_load_with_the_default() -> None:
    d = {k: v for k, v in GPFitConfig().__dict__.items() if k != "threads"}
    assert GPFitConfig.from_dict(d).threads == 1


def test_blas_threads_limits_every_blas_library_and_restores_each_one() -> None:
    """``blas_threads`` (also around every online sample) sets each BLAS library to ``k`` threads and restores
    each library's own count afterwards, also when the block raises and when calls nest."""
    import scipy.linalg.blas  # noqa: F401 - SciPy's OpenBLAS, loaded as in a fit
    from threadpoolctl import threadpool_info, threadpool_limits

    from cascgp.gp.likelihood import blas_threads

    def counts() -> list[int]:
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    with threadpool_limits(limits=2, user_api="blas"):
        before = counts()
        assert before and set(before) == {2}
        with blas_threads(1):
            assert set(counts()) == {1}
            with blas_threads(3):
                assert set(counts()) == {3}
            assert set(counts()) == {1}
            with blas_threads(1):  # already 1: nothing set, nothing restored
                assert set(counts()) == {1}
            assert set(counts()) == {1}
        assert counts() == before
        with pytest.raises(RuntimeError, match="inside"), blas_threads(1):
            raise RuntimeError("inside")
        assert counts() == before
    # OpenBLAS (pthreads) obeys one Python thread at a time; a finished block leaves it to the next thread
    with blas_threads(3):
        pass
    seen: list[list[int]] = []

    def other_thread() -> None:
        with blas_threads(3):
            seen.append(counts())

    worker = threading.Thread(target=other_thread)
    worker.start()
    worker.join()
    assert seen and set(seen[0]) == {3}
