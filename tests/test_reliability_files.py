"""Issue 12, files and data: no silent overwrite, clear loader errors, bounded reads, no orphaned temporaries,
no silent NaN from huge finite values, self-contained model files. Each test failed on the code before the fix."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cascgp.buffer import DataBuffer
from cascgp.data import DynamicsData
from cascgp.gp import GPBank, GPFitConfig
from cascgp.io import atomic_write_text, read_npz, remove_stale_temporaries
from cascgp.models import load_model, make_model
from tests.conftest import make_arm, sinusoid_data

REPO = Path(__file__).resolve().parents[1]
FAST = GPFitConfig(n_restarts=1, max_iter=15)


def _episode(seed: int) -> DynamicsData:
    return sinusoid_data(make_arm(2), 2.0, 10.0, seed=seed)


# ------------------------------------------------------------------ DataBuffer
def test_buffer_never_overwrites_after_a_gap(tmp_path: Path) -> None:
    buf = DataBuffer(tmp_path)
    for s in range(3):
        buf.append(_episode(s))
    (tmp_path / "episode_00000.npz").unlink()  # a gap: 2 files left, highest number 2
    again = DataBuffer(tmp_path)
    again.append(_episode(10))
    files = sorted(p.name for p in tmp_path.glob("episode_*.npz"))
    assert files == ["episode_00001.npz", "episode_00002.npz", "episode_00003.npz"]
    np.testing.assert_array_equal(DynamicsData.load(tmp_path / "episode_00002.npz").q, _episode(2).q)


def test_two_buffers_on_one_folder_keep_every_episode(tmp_path: Path) -> None:
    a, b = DataBuffer(tmp_path), DataBuffer(tmp_path)
    a.append(_episode(1))
    b.append(_episode(2))
    a.append(_episode(3))
    assert len(list(tmp_path.glob("episode_*.npz"))) == 3
    got = sorted(float(e.q[0, 0]) for e in DataBuffer(tmp_path).episodes)
    assert got == sorted(float(_episode(s).q[0, 0]) for s in (1, 2, 3))


def test_rejected_append_changes_nothing(tmp_path: Path) -> None:
    buf = DataBuffer(tmp_path)
    buf.append(_episode(0))
    with pytest.raises(ValueError, match="dof"):
        buf.append(sinusoid_data(make_arm(3), 1.0, 10.0, seed=0))
    assert len(buf) == 1 and len(list(tmp_path.glob("episode_*"))) == 1


# ------------------------------------------------------------------ loaders
@pytest.mark.parametrize("loader", [DynamicsData.load, load_model], ids=["data", "model"])
def test_npy_and_random_bytes_give_errors_naming_the_file(tmp_path: Path, loader) -> None:
    npy = tmp_path / "x.npy"
    np.save(npy, np.zeros(3))
    with pytest.raises(ValueError, match=r"x\.npy.*zip archive.*\.npy array"):
        loader(npy)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(ValueError, match=r"junk\.npz.*not a") as exc:
        loader(junk)
    assert "pickle" not in str(exc.value)


def test_read_npz_refuses_archives_that_inflate_beyond_the_cap(tmp_path: Path) -> None:
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        with zf.open("q.npy", "w") as fh:
            np.lib.format.write_array(fh, np.zeros(2_000_000))  # 16 MB of zeros, ~16 kB on disk
    assert bomb.stat().st_size < 100_000
    with pytest.raises(ValueError, match=r"bomb\.npz.*decompress to 15 MiB.*max_bytes"):
        read_npz(bomb, "test", max_bytes=1 << 20)
    assert read_npz(bomb, "test", max_bytes=1 << 25)["q"].shape == (2_000_000,)


def test_a_damaged_compressed_member_is_named(tmp_path: Path) -> None:
    """A DEFLATE-compressed member whose data is damaged (a zlib error, not a CRC error) names the file."""
    path = tmp_path / "damaged.npz"
    rng = np.random.default_rng(1)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        with zf.open("q.npy", "w") as fh:
            np.lib.format.write_array(fh, rng.integers(0, 4, 50_000).astype(float))  # compresses, not to nothing
    raw = bytearray(path.read_bytes())
    start = raw.index(b"q.npy") + len(b"q.npy") + 200  # inside the compressed stream, past the array header
    raw[start:start + 64] = bytes(64)
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"damaged\.npz: not a readable test \.npz file .*Error -3 while decompress"):
        read_npz(path, "test")


def test_loaders_refuse_a_zip_bomb_under_the_size_cap(tmp_path: Path) -> None:
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for k in ("q", "qd"):
            with zf.open(f"{k}.npy", "w") as fh:
                np.lib.format.write_array(fh, np.zeros(5_000_000))  # 2 x 40 MB of zeros, ~80 kB on disk
    for loader in (DynamicsData.load, load_model):
        with pytest.raises(ValueError, match=r"bomb\.npz.*decompress to 76 MiB.*zip bomb"):
            loader(bomb)


# ------------------------------------------------------------------ orphaned temporaries
def test_killed_writer_temporaries_are_removed_by_the_next_write(tmp_path: Path) -> None:
    code = ("import os, sys; from cascgp.io import atomic_write; "
            "atomic_write(sys.argv[1], lambda f: (f.write(b'x' * 1000), os.kill(os.getpid(), 9)))")
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "big.bin")], cwd=REPO)
    assert r.returncode == -9
    left = [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert len(left) == 1 and not (tmp_path / "big.bin").exists()
    host = left[0].name.split(".")[-3].split("-")[0]
    mine = tmp_path / f".other.{host}-{os.getpid()}.abc123.tmp"  # a live writer's (ours): kept
    mine.write_text("keep")
    atomic_write_text(tmp_path / "next.txt", "ok")
    assert not left[0].exists() and mine.exists()
    assert (tmp_path / "next.txt").read_text() == "ok"
    assert remove_stale_temporaries(tmp_path) == []


# ------------------------------------------------------------------ huge finite values
@pytest.mark.parametrize("name", ["np-standard", "np-inward"])
def test_huge_finite_torques_are_refused_naming_the_field(name: str) -> None:
    d = _episode(0)
    huge = DynamicsData(q=d.q, qd=d.qd, qdd=d.qdd, tau=d.tau * 1e156, t=d.t)
    with pytest.raises(ValueError, match=r"data\.tau: values too large"):
        make_model(name, 2, gp_config=FAST).fit(huge)
    with pytest.raises(ValueError, match=r"y\[0\]: values too large"):
        GPBank(FAST).fit([d.q], [d.tau[:, 0] * 1e156])


def test_sp_predict_one_refuses_huge_velocities_like_predict() -> None:
    arm = make_arm(2)
    m = make_model("sp-inward", 2, arm, gp_config=FAST).fit(_episode(0))
    q, qdd = np.zeros(2), np.zeros(2)
    qd = np.full(2, 1e160)
    with pytest.raises(ValueError, match="non-finite"):
        m.predict(q, qd, qdd)
    with pytest.raises(ValueError, match="non-finite"):
        m.predict_one(q, qd, qdd)


# ------------------------------------------------------------------ self-contained model files
def test_sp_model_file_loads_from_another_folder_without_the_urdf(tmp_path: Path, monkeypatch) -> None:
    from cascgp.rbd import load_nominal

    src = REPO / "jaco_env" / "assets" / "jaco2_nominal.urdf"
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(src, work / "arm.urdf")
    shutil.copy(src.with_suffix(".json"), work / "arm.json")
    monkeypatch.chdir(work)
    rbd = load_nominal("arm.urdf")  # a cwd-relative path, as a user would type it
    rng = np.random.default_rng(0)
    q, qd, qdd = (rng.uniform(-1, 1, (40, 6)) for _ in range(3))
    tau = rbd.inverse_dynamics(q, qd, qdd) + 0.1 * np.sin(q)
    data = DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=np.arange(40) * 0.1)
    m = make_model("sp-standard", 6, rbd, gp_config=FAST).fit(data)
    m.save("model.npz")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.move(str(work / "model.npz"), elsewhere / "model.npz")
    shutil.rmtree(work)
    monkeypatch.chdir(elsewhere)
    back = load_model("model.npz")
    np.testing.assert_allclose(back.predict(q[:5], qd[:5], qdd[:5])[0], m.predict(q[:5], qd[:5], qdd[:5])[0],
                               rtol=1e-10, atol=1e-10)
    assert back.rbd.meta == rbd.meta
    np.testing.assert_array_equal(back.rbd.armature, rbd.armature)


def test_damaged_embedded_urdf_is_reported(tmp_path: Path) -> None:
    from cascgp.rbd import load_nominal

    rbd = load_nominal(REPO / "jaco_env" / "assets" / "jaco2_nominal.urdf")
    rng = np.random.default_rng(1)
    q, qd, qdd = (rng.uniform(-1, 1, (30, 6)) for _ in range(3))
    data = DynamicsData(q=q, qd=qd, qdd=qdd, tau=rbd.inverse_dynamics(q, qd, qdd) + 0.05, t=np.arange(30) * 0.1)
    path = make_model("sp-standard", 6, rbd, gp_config=FAST).fit(data).save(tmp_path / "m.npz")
    z = dict(np.load(path))
    z["rbd/urdf"] = np.array(str(z["rbd/urdf"]).replace("<robot", "<robot x='1'", 1))
    np.savez(tmp_path / "bad.npz", **z)
    with pytest.raises(ValueError, match=r"bad\.npz.*SHA-256"):
        load_model(tmp_path / "bad.npz")


def test_complex_inputs_are_refused_not_cast() -> None:
    d = _episode(0)
    with pytest.raises(TypeError, match=r"DynamicsData\.q: expected a real numeric"):
        DynamicsData(q=d.q + 1j, qd=d.qd, qdd=d.qdd, tau=d.tau, t=d.t)
    m = make_model("np-standard", 2, gp_config=FAST).fit(d)
    z = np.zeros(2)
    with pytest.raises(TypeError, match="qd: expected a real numeric"):
        m.predict(z, z + 1j, z)
    with pytest.raises(TypeError, match="q: expected a real numeric"):
        m.predict_one(z + 1j, z, z)


# ------------------------------------------------------------------ controller
def test_controller_falls_back_on_any_model_exception_and_refuses_infinite_limits() -> None:
    from cascgp.controller import FeedforwardController

    class Broken:
        dof, name = 2, "broken"

        def predict_one(self, *a, **k):
            raise RuntimeError("model bug")

    class Nominal:
        dof = 2

        def inverse_dynamics(self, q, qd, qdd):
            return np.array([1.0, -1.0])

    def ref(t):
        return np.zeros(2), np.zeros(2), np.zeros(2)

    ctrl = FeedforwardController(Broken(), 1.0, 0.1, np.array([5.0, 5.0]), fallback=Nominal())
    np.testing.assert_allclose(ctrl(0.0, np.zeros(2), np.zeros(2), ref), [1.0, -1.0])
    assert ctrl.n_fallbacks == 1 and "RuntimeError: model bug" in ctrl.last_model_error
    for bad in (np.array([np.inf, 1.0]), np.array([1.0, np.nan]), np.array([1 + 1j, 1.0]), np.array([])):
        with pytest.raises(ValueError, match="torque_limits"):
            FeedforwardController(None, 1.0, 0.1, bad)


def test_atomic_writes_get_the_mode_open_would_give(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        import importlib

        import cascgp.io as cio

        importlib.reload(cio)  # the umask is read at import
        p = cio.atomic_write_text(tmp_path / "a.txt", "x")
        assert (p.stat().st_mode & 0o777) == 0o640
    finally:
        os.umask(old)
        importlib.reload(cio)
    assert (atomic_write_text(tmp_path / "b.txt", "x").stat().st_mode & 0o777) == 0o666 & ~old
