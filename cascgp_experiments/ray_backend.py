"""The Ray backend of :mod:`cascgp_experiments.execution`: connecting to a cluster (and its token
authentication) and running the jobs as Ray tasks. Ray is an optional extra (``ray``);
nothing here imports it until a run asks for it.

Ray token authentication (as in Ray 2.60, the version the extra pins): ``ray start --head`` turns it on when a
token exists (``~/.ray/auth_token``, which Ray also writes the first time a local instance starts, e.g.
``--ray local``), and ``ray.init`` sends the token only when ``RAY_AUTH_MODE=token`` or for
``address="auto"``, never on its own for an explicit ``HOST:PORT``. So that ``--ray HOST:PORT`` works
like ``--ray auto`` for a cluster on this machine, :func:`run_jobs` (and :func:`check_args`) set
``RAY_AUTH_MODE=token`` in this process when the address is one of this machine's, ``RAY_AUTH_MODE`` is
unset and Ray finds a token (``RAY_AUTH_TOKEN``, ``RAY_AUTH_TOKEN_PATH`` or ``~/.ray/auth_token``). The
token is never sent on its own to another machine's address (as Ray, which leaves that to the user):
there a cluster that wants a token is a :class:`RayAuthenticationError` that says what to set, not
Ray's traceback.
"""

from __future__ import annotations

import os
import sys
from typing import Any, Callable, Sequence

from tqdm import tqdm

from cascgp_experiments.common import install_hint

__all__ = ["RayAuthenticationError", "RAY_AUTH_MODE_VAR", "RAY_TOKEN_PLACES", "import_ray", "ray_connect", "run_ray"]


class RayAuthenticationError(RuntimeError):
    """The Ray cluster at ``address`` refused this process: it wants a token (Ray's token authentication) that
    this process did not send, or not the one it sent. The message says which and what to set; ``auth_mode``
    is ``RAY_AUTH_MODE`` as this process had it (``None``: unset), ``ray_error`` Ray's own message."""

    def __init__(self, message: str, address: str, auth_mode: str | None, ray_error: str) -> None:
        super().__init__(message)
        self.address = address
        self.auth_mode = auth_mode
        self.ray_error = ray_error



def import_ray():
    try:
        import ray
    except ImportError as exc:
        raise ImportError(f"--ray needs Ray, which is not installed: {install_hint('ray')}") from exc
    return ray


#: Ray's variable for its authentication mode: ``token`` makes this process send its token.
RAY_AUTH_MODE_VAR = "RAY_AUTH_MODE"
#: Where Ray looks for a token, in its order (for messages).
RAY_TOKEN_PLACES = "RAY_AUTH_TOKEN, the file named by RAY_AUTH_TOKEN_PATH, or ~/.ray/auth_token"


def _address_host(address: str) -> str | None:
    """The host of a Ray address ``[scheme://]HOST[:PORT]`` (``[...]`` around an IPv6 host); ``None`` if empty."""
    rest = address.split("://", 1)[-1].strip()
    if rest.startswith("["):
        return rest[1:rest.index("]")] if "]" in rest else None
    host = rest.rsplit(":", 1)[0] if rest.count(":") == 1 else rest
    return host or None


def _is_this_machine(host: str) -> bool:
    """True when ``host`` names an address of this machine (loopback or one of its interfaces): a socket can
    be bound to it. A name that does not resolve is not this machine."""
    import socket

    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return False
    for family, _, _, _, sockaddr in infos:
        try:
            with socket.socket(family, socket.SOCK_STREAM) as s:
                s.bind((sockaddr[0], 0))
            return True
        except OSError:
            continue
    return False


def _ray_has_token() -> bool | None:
    """Whether Ray finds an authentication token (:data:`RAY_TOKEN_PLACES`), asked to Ray's own loader;
    ``None`` for a Ray without token authentication (older versions)."""
    try:
        from ray._raylet import AuthenticationTokenLoader
    except ImportError:
        return None
    return bool(AuthenticationTokenLoader.instance().has_token(ignore_auth_mode=True))


def _use_local_token(address: str) -> str | None:
    """For an explicit address of this machine, with ``RAY_AUTH_MODE`` unset and a token at hand: set
    ``RAY_AUTH_MODE=token`` in this process (and for its children), as ``ray.init(address="auto")`` and
    ``ray start`` do for a cluster they find here. Return a note saying so, or ``None`` when nothing changed.

    Another machine's address is left alone: the local token is not sent there unasked."""
    if address in ("local", "auto") or os.environ.get(RAY_AUTH_MODE_VAR) is not None:
        return None
    host = _address_host(address)
    if host is None or not _is_this_machine(host) or not _ray_has_token():
        return None
    from ray._raylet import Config

    os.environ[RAY_AUTH_MODE_VAR] = "token"
    Config.initialize("")  # Ray reads its configuration once: make it see the new mode (as Ray's own code does)
    return (f"--ray {address} is on this machine and Ray finds a token here ({RAY_TOKEN_PLACES}): connecting "
            f"with {RAY_AUTH_MODE_VAR}=token, as --ray auto does")


def _auth_failure(exc: BaseException) -> str | None:
    """Ray's message when ``exc`` (or an exception it was raised from) is a refused or missing token, else
    ``None``. ``ray.init`` reports a refused token as a ``ConnectionError`` whose cause holds the
    ``AuthenticationError`` as text (Ray's traceback of its last attempt), hence the text match."""
    markers = ("AuthenticationError", "InvalidAuthToken", "Token authentication is enabled but")
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        lines = str(e).splitlines()
        if type(e).__name__ == "AuthenticationError":
            return _first_sentence(lines[0]) if lines else type(e).__name__
        for line in lines:
            if any(m in line for m in markers):
                return _first_sentence(line.split("AuthenticationError: ", 1)[-1])
        e = e.__cause__ or e.__context__
    return None


def _first_sentence(text: str) -> str:
    """Ray's error without the help it appends (" Note: ...", " Ensure that ...") and the final full stop."""
    for cut in (" Note: ", " Ensure that "):
        text = text.split(cut, 1)[0]
    return text.strip().rstrip(".")


def _auth_message(address: str, ray_error: str) -> str:
    """What went wrong with the token at ``address`` and what to set, for the mode this process ran in."""
    mode = os.environ.get(RAY_AUTH_MODE_VAR)
    has_token = _ray_has_token()
    head = f"--ray {address}: the Ray cluster refused this process (Ray: {ray_error}). "
    if mode is None or mode.lower() != "token":
        why = ("RAY_AUTH_MODE is unset, so no token was sent: the cluster has token authentication on "
               "(`ray start --head` turns it on when ~/.ray/auth_token exists), and Ray sends the token to an "
               "explicit HOST:PORT only with RAY_AUTH_MODE=token"
               if mode is None else
               f"RAY_AUTH_MODE={mode} is set, so no token was sent, but the cluster has token authentication on")
        local = _address_host(address) is not None and _is_this_machine(_address_host(address) or "")
        fix = ("Fix: run with RAY_AUTH_MODE=token (and the head node's token in "
               f"{RAY_TOKEN_PLACES}; `ray get-auth-token` on the head prints it), or use --ray auto on the head node")
        if mode is not None and local and has_token:
            fix = "Fix: unset RAY_AUTH_MODE (a cluster on this machine then gets the local token), or set it to token"
        return f"{head}{why}. {fix}."
    what = ("RAY_AUTH_MODE=token, but the token sent is not this cluster's" if has_token else
            f"RAY_AUTH_MODE=token, but no token was found ({RAY_TOKEN_PLACES})")
    return (f"{head}{what}. Fix: use the head node's token (`ray get-auth-token` on the head prints it): put it "
            f"in ~/.ray/auth_token here, or set RAY_AUTH_TOKEN / RAY_AUTH_TOKEN_PATH.")


def _check_something_listens(address: str) -> None:
    """``ConnectionError`` when ``address`` is ``HOST:PORT`` of this machine and nothing listens on that port:
    ``ray.init`` would wait for the cluster's control store without end there (measured: over 7 min), while a
    refused connection answers at once. Other addresses (``auto``, ``ray://``, other machines) go to Ray as
    they are."""
    import socket

    if "://" in address or address in ("auto", "local"):
        return
    host = _address_host(address)
    port_text = address.rsplit(":", 1)[-1] if ":" in address.rstrip("]") else ""
    if host is None or not port_text.isdigit() or not _is_this_machine(host):
        return
    try:
        with socket.create_connection((host, int(port_text)), timeout=5):
            pass
    except ConnectionRefusedError:
        raise ConnectionError(f"nothing listens on port {port_text} of this machine ({host}), so no Ray cluster "
                              "runs there") from None
    except OSError:  # a timeout or anything else: let Ray try and report
        return


def ray_connect(address: str, workers: int) -> bool:
    """Connect to (``"local"``: start) Ray unless connected already; True when this call connected.

    ``"local"`` is passed to Ray as ``address="local"``: always a new instance, never a cluster that
    ``ray start`` left running on this machine (which ``ray.init()`` without an address would join, and
    refuse ``num_cpus`` for). For a cluster address, :func:`_use_local_token` first; a refused or missing
    token raises :class:`RayAuthenticationError` (Ray's traceback left out, its message kept)."""
    import logging

    ray = import_ray()
    if ray.is_initialized():
        return False
    if address == "local":
        ray.init(address="local", num_cpus=workers, include_dashboard=False, logging_level=logging.WARNING)
        return True
    _check_something_listens(address)
    note = _use_local_token(address)
    if note:
        tqdm.write(note, file=sys.stderr)
    try:
        ray.init(address=address, logging_level=logging.WARNING)
    except Exception as exc:  # only a refused token is translated; anything else goes on as it is
        ray_error = _auth_failure(exc)
        if ray_error is None:
            raise
        mode = os.environ.get(RAY_AUTH_MODE_VAR)
        raise RayAuthenticationError(_auth_message(address, ray_error), address, mode, ray_error) from None
    return True


def run_ray(fn: Callable, jobs: Sequence[Any], todo: list[int], workers: int, address: str, progress: Any,
            finished: Callable[[int, tuple], bool]) -> None:
    """:func:`cascgp_experiments.execution.run_jobs`'s Ray backend: jobs ``todo`` as Ray tasks of one CPU each;
    ``finished(i, outcome)`` records job ``i``'s outcome and says whether to submit it again."""
    from cascgp_experiments.execution import JobError, _call, _Drain

    ray = import_ray()
    from ray.util.queue import Queue as RayQueue

    started = ray_connect(address, workers)
    error: BaseException | None = None
    channel = RayQueue()
    drain = _Drain(channel, progress, lambda: channel.get(block=True, timeout=0.2))
    drain.start()
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(_call)
        running = {remote.remote(fn, jobs[i], i, 0, channel): i for i in todo}
        while running:
            done, _ = ray.wait(list(running), num_returns=1)
            for ref in done:
                i = running.pop(ref)
                try:
                    out = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - the worker died (not an error raised by the job)
                    out = ("error", f"{type(exc).__name__}: {exc}", 0.0)
                try:
                    again = finished(i, out)
                except JobError as exc:
                    if error is None:
                        error = exc
                        for r in running:
                            ray.cancel(r)
                    continue
                if again and error is None:
                    running[remote.remote(fn, jobs[i], i, progress.attempt[i], channel)] = i
            if error is not None:
                # cancelled tasks raise on get (ray.cancel interrupts the running ones too); any that had
                # finished in the meantime are cached
                for ref in list(running):
                    i = running.pop(ref)
                    try:
                        out = ray.get(ref)
                        if out[0] == "ok":
                            finished(i, out)
                    except Exception:  # noqa: BLE001
                        pass
    finally:
        drain.stop()
        try:
            channel.shutdown()
        except Exception:  # noqa: BLE001
            pass
        if started:
            ray.shutdown()
    if error is not None:
        raise error
