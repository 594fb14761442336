"""The Ray backend's token authentication: the helpers without a cluster (default suite) and a real Ray cluster
(``ray start --head`` on 127.0.0.1, with token authentication on) reached by ``--ray 127.0.0.1:PORT`` (slow).

Ray 2.60 writes a token to ``~/.ray/auth_token`` the first time it starts a local instance; here it reads one
from a temporary file instead (``RAY_AUTH_TOKEN_PATH``), so that running the tests leaves the user's home alone (a
token there turns token authentication on at the user's next ``ray start --head``). Tests that need Ray skip
where it is not installed.
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Iterator

import pytest
from execution_helpers import ray_token_outside_home  # noqa: F401 (autouse: Ray's token outside the home)
from execution_helpers import RAY_AUTH_VARS, REPO, needs_ray, subprocess_env
from test_execution import seeded_job

from cascgp_experiments.execution import run_jobs


# --------------------------------------------------------------------------- Ray token authentication
def test_ray_address_host_and_this_machine() -> None:
    from cascgp_experiments.ray_backend import _address_host, _is_this_machine

    assert _address_host("127.0.0.1:6379") == "127.0.0.1"
    assert _address_host("ray://head.example:10001") == "head.example"
    assert _address_host("[::1]:6379") == "::1"
    assert _address_host(":6379") is None
    assert _is_this_machine("127.0.0.1") and _is_this_machine("localhost")
    assert not _is_this_machine("198.51.100.7")  # TEST-NET-2: never an address of this machine
    assert not _is_this_machine("no-such-host.invalid")


def test_the_local_token_is_never_sent_unasked(monkeypatch) -> None:
    """RAY_AUTH_MODE is set to token only for an explicit address of this machine with the mode unset: not for
    another machine's address, not over a mode the user set, not for 'auto'/'local' (Ray's own business)."""
    import cascgp_experiments.ray_backend as ex

    monkeypatch.setattr(ex, "_ray_has_token", lambda: True)
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    for address in ("198.51.100.7:6379", "no-such-host.invalid:6379", "auto", "local"):
        assert ex._use_local_token(address) is None
        assert "RAY_AUTH_MODE" not in os.environ
    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")
    assert ex._use_local_token("127.0.0.1:6379") is None
    assert os.environ["RAY_AUTH_MODE"] == "disabled"


# ray.init's error for a refused token, as Ray 2.60 raises it: a ConnectionError from a RuntimeError that holds
# the traceback of the last attempt as text
_RAY_REFUSED = ("Failed to connect to GCS. Last connection error: Traceback (most recent call last):\n"
                "  File \"python/ray/includes/common.pxi\", line 119, in ray._raylet.check_status\n"
                "ray.exceptions.AuthenticationError: RPC error: InvalidAuthToken: Authentication token is missing or "
                "incorrect. Note: RAY_AUTH_MODE is currently 'disabled' (not 'token'). Ensure that the token for the "
                "cluster is available in a local file\n")


def _ray_style_error(text: str) -> ConnectionError:
    try:
        try:
            raise RuntimeError(text)
        except RuntimeError as inner:
            raise ConnectionError("Failed to connect to Ray cluster at 192.0.2.9:6379") from inner
    except ConnectionError as exc:
        return exc


def test_refused_token_is_recognised_and_the_message_names_the_fix(monkeypatch) -> None:
    import cascgp_experiments.ray_backend as ex

    err = ex._auth_failure(_ray_style_error(_RAY_REFUSED))
    assert err == "RPC error: InvalidAuthToken: Authentication token is missing or incorrect"
    assert ex._auth_failure(_ray_style_error("Failed to connect to GCS. Last connection error: timed out")) is None
    assert ex._auth_failure(ConnectionError("Could not find any running Ray instance")) is None

    monkeypatch.setattr(ex, "_is_this_machine", lambda host: False)
    monkeypatch.setattr(ex, "_ray_has_token", lambda: True)
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)  # the reported case: a cluster elsewhere, no mode set
    msg = ex._auth_message("10.1.2.3:6379", err)
    assert msg.startswith("--ray 10.1.2.3:6379: the Ray cluster refused this process")
    assert "RAY_AUTH_MODE is unset" in msg and "RAY_AUTH_MODE=token" in msg and "--ray auto" in msg
    assert "Traceback" not in msg and "\n" not in msg
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    assert "not this cluster's" in ex._auth_message("10.1.2.3:6379", err)
    monkeypatch.setattr(ex, "_ray_has_token", lambda: False)
    assert "no token was found" in ex._auth_message("10.1.2.3:6379", err)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _ray_env(home: Path) -> dict[str, str]:
    """The environment of a process of the test cluster: its own HOME (with or without a token), none of Ray's
    token or address variables of the caller."""
    env = subprocess_env()
    for k in RAY_AUTH_VARS:
        env.pop(k, None)
    env["HOME"] = str(home)
    env["RAY_USAGE_STATS_ENABLED"] = "0"
    return env


@pytest.fixture(scope="module")
def ray_head() -> Iterator[dict[str, Any]]:
    """A real Ray head on this machine (``ray start --head --block``, 127.0.0.1, its own process group and temp
    folder) whose HOME holds ``~/.ray/auth_token``, so that Ray 2.60 turns token authentication on, as it does
    for a user who once ran a local Ray instance. Stopped afterwards by killing its process group (``ray stop``
    would stop every Ray process on the machine, other users' too)."""
    needs_ray()
    ray_cli = Path(sys.executable).with_name("ray")
    if not ray_cli.exists():
        ray_cli = Path(shutil.which("ray") or "ray")
    root = Path(tempfile.mkdtemp(prefix="cgray", dir="/tmp"))  # short: Ray's socket paths must fit in 107 bytes
    home = root / "home"
    (home / ".ray").mkdir(parents=True)
    (home / ".ray" / "auth_token").write_text(secrets.token_hex(32))
    port = _free_port()
    log_path = root / "head.log"
    with open(log_path, "w") as log:
        head = subprocess.Popen(
            [str(ray_cli), "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}", "--num-cpus=2",
             "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={root / 'ray'}", "--block"],
            env=_ray_env(home), cwd=REPO, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while "Ray runtime started" not in log_path.read_text():
            if head.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"ray start --head did not start (exit status {head.poll()}):\n"
                            f"{log_path.read_text()[-3000:]}")
            time.sleep(0.2)
        yield {"address": f"127.0.0.1:{port}", "home": home, "root": root}
    finally:
        try:
            os.killpg(head.pid, signal.SIGKILL)  # the head and every process it started (SIGTERM: a 30 s drain)
        except ProcessLookupError:
            pass
        head.wait(timeout=60)
        shutil.rmtree(root, ignore_errors=True)


_RAY_DRIVER = """
import json, os, sys
import cascgp_experiments.execution as ex
import cascgp_experiments.ray_backend as rb
from test_execution import seeded_job
if sys.argv[2] == "elsewhere":
    rb._is_this_machine = lambda host: False  # stands for a cluster on another machine
try:
    res = ex.run_jobs(seeded_job, [{"x": x, "seed": 100 + x} for x in range(3)], ray_address=sys.argv[1],
                      show_progress=False)
except ex.RayAuthenticationError as exc:
    print(json.dumps({"error": str(exc), "auth_mode": exc.auth_mode, "env_mode": os.environ.get("RAY_AUTH_MODE")}))
else:
    print(json.dumps({"backend": res.backend, "chol": [r["chol"] for r in res], "x": [r["x"] for r in res]}))
"""


def _driver(head: dict[str, Any], where: str, **env_vars: str) -> tuple[dict, subprocess.CompletedProcess]:
    import json

    env = _ray_env(head["home"]) | env_vars
    run = subprocess.run([sys.executable, "-c", _RAY_DRIVER, head["address"], where], env=env, cwd=REPO,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1]), run


@pytest.mark.slow
def test_ray_cluster_here_with_token_auth_runs_the_jobs(ray_head) -> None:
    """The reported failure: --ray HOST:PORT to a head started with a token in ~/.ray/auth_token, RAY_AUTH_MODE
    unset. Raw Ray (an explicit address) sends no token and is refused; here it connects and runs the jobs."""
    out, run = _driver(ray_head, "here")
    assert out.get("backend") == "ray", out
    ref = run_jobs(seeded_job, [{"x": x, "seed": 100 + x} for x in range(3)], workers=1, show_progress=False)
    assert out["x"] == [r["x"] for r in ref] and out["chol"] == [r["chol"] for r in ref]
    assert "connecting with RAY_AUTH_MODE=token" in run.stderr


@pytest.mark.slow
def test_ray_cluster_elsewhere_with_token_auth_is_a_clear_error(ray_head) -> None:
    """The same cluster seen as another machine's: the local token is not sent unasked, and the error says to
    set RAY_AUTH_MODE=token (or use --ray auto on the head) instead of Ray's traceback."""
    out, run = _driver(ray_head, "elsewhere", RAY_gcs_server_port_wait_time_s="5")  # Ray retries 20 s by default
    assert "error" in out, out
    assert out["auth_mode"] is None and out["env_mode"] is None
    assert "RAY_AUTH_MODE=token" in out["error"] and "--ray auto" in out["error"]
    assert "InvalidAuthToken" in out["error"]  # Ray's own reason, kept
    assert "Traceback" not in run.stderr


@pytest.mark.slow
@pytest.mark.parametrize("case", ["mode-disabled", "wrong-token"])
def test_ray_cluster_refusing_the_command_is_a_one_line_error(ray_head, tmp_path: Path, case: str) -> None:
    """A command line (here: the data collection) that the cluster refuses ends at argument checking, exit
    status 2, with one ``error:`` line naming the fix: no traceback, nothing written."""
    env = _ray_env(ray_head["home"]) | {"RAY_gcs_server_port_wait_time_s": "5"}
    if case == "mode-disabled":
        env["RAY_AUTH_MODE"] = "disabled"
        expect = ["RAY_AUTH_MODE=disabled is set", "unset RAY_AUTH_MODE"]
    else:
        env |= {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
        expect = ["not this cluster's", "ray get-auth-token"]
    address = ray_head["address"]
    run = subprocess.run([sys.executable, "-m", "scripts.collect_jaco_data", "--out", str(tmp_path / "data"),
                          "--smoke", "--ray", address], env=env, cwd=REPO, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 2, run.stderr[-3000:]
    assert f"error: --ray {address}: the Ray cluster refused this process" in run.stderr
    for text in expect:
        assert text in run.stderr, run.stderr[-3000:]
    assert "Traceback" not in run.stderr
    assert not (tmp_path / "data").exists()


def test_an_address_of_this_machine_where_nothing_listens_is_refused_at_once() -> None:
    """``ray.init`` waits without end for a cluster at a port of this machine where none runs; the connection is
    tried first, and a refused one is a ConnectionError naming the port. Other addresses go to Ray unchanged."""
    from cascgp_experiments.ray_backend import _check_something_listens

    port = _free_port()  # bound and closed again: nothing listens there
    with pytest.raises(ConnectionError, match=f"nothing listens on port {port} of this machine"):
        _check_something_listens(f"127.0.0.1:{port}")
    with socket.socket() as server:  # something listens: passed on to Ray
        server.bind(("127.0.0.1", 0))
        server.listen()
        _check_something_listens(f"127.0.0.1:{server.getsockname()[1]}")
    for address in ("auto", "ray://127.0.0.1:1", "198.51.100.7:6379", "127.0.0.1"):
        _check_something_listens(address)  # not tried here
