"""The Ray backend of :func:`piga.io.pool.run_pool`: each job a Ray task of one CPU and one torch thread.

Ray is an optional extra (``pip install -e '.[ray]'``), imported here only, when a run asks for it.
:func:`connect` joins a cluster once per process (or, for "auto", the instance running on this machine, or
starts one), after checking that a Ray head answers at the address, so that a wrong address is refused in
seconds rather than after Ray's own minutes of retries. :func:`run_ray` submits every job at once
(Ray runs as many as the cluster has free CPUs), each in this process's working directory (so every machine
needs the same checkout at the same path), gives each result to ``on_result`` in this process as it ends,
and returns the results in the order of the jobs.

A job that raises (or whose worker process dies) stops the run: :class:`~piga.io.pool.JobFailed` names
it, the other tasks are cancelled, and the results that ended before it were already handed to
``on_result``. Jobs are not retried: they are deterministic, and a run continues from its records.
Ctrl-C (or SIGTERM through :func:`piga.cli.common.run_cli`) cancels the tasks the same way. After
either, a Ray instance that this process started is shut down, and a cluster it joined is left,
running.

Results do not depend on the backend as long as each job seeds itself and sets what it needs (the
jobs of piga do): a task runs in a reused worker process that was not forked from this one.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from tqdm.auto import tqdm

from piga.io.pool import BackendError, JobFailed, host_port

Spec = TypeVar("Spec")
Result = TypeVar("Result")

#: Seconds to wait for a Ray head to answer before the address is refused.
CONNECT_TIMEOUT_S = 5.0
#: The line that says how to install Ray.
INSTALL = "Ray is not installed: pip install -e '.[ray]'"

_started_here = False
"""Whether this process connected to Ray through :func:`connect` (and so disconnects, or stops the instance it started)."""


def _ray() -> Any:
    """The ray module, or :class:`BackendError` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise BackendError(INSTALL) from None
    return ray


def check_ray_head(host: str, port: int, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Raises :class:`BackendError` unless a Ray head (its GCS server) answers at ``host:port`` within ``timeout``
    seconds: an unknown host, nothing listening, no answer, or a server of another kind; and when the head asks
    for an authentication token that this machine does not hold.

    A TCP connection first (for a clear reason when there is none), then one gRPC call that every Ray head
    serves (``GetClusterId``): a head answers it, or refuses it for want of a token; another server does not
    know it. Without grpcio (a dependency of tensorboard, so of piga) only the TCP connection is checked.
    """
    where = f"{host}:{port}"
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except socket.gaierror as exc:
        raise BackendError(f"no Ray cluster at {where}: unknown host ({exc.strerror})") from None
    except TimeoutError:
        raise BackendError(f"no Ray cluster at {where}: no answer within {timeout:g} s") from None
    except OSError as exc:
        raise BackendError(f"no Ray cluster at {where}: {exc.strerror or exc.__class__.__name__}") from None
    try:
        import grpc
    except ImportError:
        return
    with grpc.insecure_channel(f"[{host}]:{port}" if ":" in host else where) as channel:
        try:
            channel.unary_unary("/ray.rpc.NodeInfoGcsService/GetClusterId")(b"", timeout=timeout)
        except grpc.RpcError as err:
            code = err.code()  # type: ignore[attr-defined]
            if code == grpc.StatusCode.UNAUTHENTICATED:
                if not _token_available():
                    raise BackendError(f"the Ray cluster at {where} asks for an authentication token, and this machine "
                                       "has none: copy the head's ~/.ray/auth_token here (or set RAY_AUTH_TOKEN)") from None
            elif code == grpc.StatusCode.DEADLINE_EXCEEDED:
                raise BackendError(f"no Ray cluster at {where}: no answer within {timeout:g} s") from None
            else:
                raise BackendError(f"no Ray cluster at {where}: something answers there, but not a Ray head "
                                   f"({code.name})") from None


def _token_available() -> bool:
    """Whether this machine holds a Ray authentication token (the places Ray reads it from)."""
    if os.environ.get("RAY_AUTH_TOKEN"):
        return True
    path = os.environ.get("RAY_AUTH_TOKEN_PATH")
    return Path(path).expanduser().is_file() if path else (Path.home() / ".ray" / "auth_token").is_file()


def _use_token_if_any(starts_local: bool) -> None:
    """Token authentication, where this machine holds a token or Ray starts here (and makes one).

    A new local instance takes token authentication by default (and says so in a warning), and so does a
    cluster started by ``ray start --head``; a driver that joins it must send the token, which Ray reads only
    when ``RAY_AUTH_MODE`` says so. A mode set by the user is left as it is.
    """
    if "RAY_AUTH_MODE" in os.environ or not (starts_local or _token_available()):
        return
    os.environ["RAY_AUTH_MODE"] = "token"
    try:  # Ray caches its settings when imported: read them again
        from ray._raylet import Config

        Config.initialize("")
    except (ImportError, AttributeError):
        pass


def _local_instance() -> str:
    """Where "auto" goes: ``$RAY_ADDRESS`` if set; else the Ray instance that ``ray start`` last started on this
    machine, if it still answers; else "local" (start one). Ray's own "auto" trusts the address ``ray start``
    recorded even when that instance is gone (stopped without ``ray stop``), and then retries it for minutes."""
    if (given := os.environ.get("RAY_ADDRESS")) and given != "auto":
        return given
    try:
        from ray._private.services import find_bootstrap_address

        recorded = find_bootstrap_address(None)
    except Exception:  # Ray's internals moved: start an instance of this command's own
        return "local"
    if not recorded:
        return "local"
    try:
        check_ray_head(*host_port(recorded))
    except (BackendError, ValueError):
        return "local"
    return recorded


def connect(address: str = "auto") -> None:
    """Joins the Ray cluster at ``address`` (HOST:PORT), or for "auto" the instance that runs on this machine
    (or ``$RAY_ADDRESS``), starting one when there is none; once per process (a connection already made, by
    this function or by the caller, is used as it is). :class:`BackendError` when Ray is not installed, no Ray
    head answers at the address, or Ray refuses the connection (its message, on one line)."""
    global _started_here
    ray = _ray()
    if ray.is_initialized():
        return
    target = address if address != "auto" else _local_instance()
    if target != "local":
        try:
            check_ray_head(*host_port(target))
        except ValueError as exc:
            raise BackendError(str(exc)) from None
    _use_token_if_any(starts_local=target == "local")
    main_thread = threading.current_thread() is threading.main_thread()
    sigterm = signal.getsignal(signal.SIGTERM) if main_thread else None
    try:
        ray.init(address=target, logging_level=logging.WARNING,
                 **({"include_dashboard": False} if target == "local" else {}))
    except (ConnectionError, RuntimeError, ValueError) as exc:
        message = " ".join(str(exc).split())[:300]
        raise BackendError(f"Ray could not connect to {address}: {message}") from None
    finally:
        # Ray takes SIGTERM over (to die with a stack dump); the caller's handler is put back (run_cli's raises
        # KeyboardInterrupt), and where there was none, SIGTERM exits through SystemExit, so that run_ray cancels
        # its tasks and stops the instance it started rather than leaving Ray's agents behind.
        if main_thread:
            signal.signal(signal.SIGTERM, sigterm if sigterm not in (signal.SIG_DFL, None) else _exit_on_sigterm)
    _started_here = True


def _exit_on_sigterm(signum: int, frame: object) -> None:
    raise SystemExit(128 + signum)


def disconnect() -> None:
    """Leaves the cluster that :func:`connect` joined, stopping the local instance it started (if it started
    one); a connection made by the caller is left as it is."""
    global _started_here
    if _started_here:
        _started_here = False
        _ray().shutdown()


def _run_job(function: Callable[[Spec], Result], spec: Spec, folder: str) -> Result:
    """One job in a Ray worker: in ``folder`` (the driver's working directory, so that relative paths mean what
    they mean there), with one torch thread (the task has one CPU), ``function(spec)``."""
    import torch

    if os.getcwd() != folder:
        try:
            os.chdir(folder)
        except OSError:
            raise FileNotFoundError(f"{socket.gethostname()} has no folder {folder}, where the run was started: every "
                                    "machine of the cluster needs the same checkout at the same path") from None
    torch.set_num_threads(1)
    return function(spec)


def run_ray(function: Callable[[Spec], Result], specs: Sequence[Spec], names: Sequence[str], progress: bool = True,
            desc: str = "jobs", on_result: Callable[[int, Result], None] | None = None,
            address: str = "auto") -> list[Result]:
    """:func:`piga.io.pool.run_pool` on Ray: ``function(spec)`` for each of ``specs`` as a task of one CPU
    (:func:`connect` to ``address`` first); the results in the order of ``specs``, each handed to
    ``on_result(i, result)`` here as it ends; a failure raises :class:`JobFailed` with ``names[i]``."""
    ray = _ray()
    connect(address)
    if not specs:
        return []
    task = ray.remote(num_cpus=1, max_retries=0)(_run_job)
    shared = ray.put(function)
    refs = [task.remote(shared, spec, os.getcwd()) for spec in specs]
    index = {ref: i for i, ref in enumerate(refs)}
    pending = list(refs)
    results: list[Any] = [None] * len(specs)
    try:
        with tqdm(total=len(specs), desc=desc, disable=not progress) as bar:
            while pending:
                # a timeout, so that Ctrl-C is seen between waits
                ready, pending = ray.wait(pending, num_returns=1, timeout=1.0)
                for ref in ready:
                    i = index[ref]
                    try:
                        results[i] = ray.get(ref)
                    except ray.exceptions.RayTaskError as err:  # the job raised: its own exception, and the traceback
                        raise JobFailed(names[i], err.cause if err.cause is not None else err) from err
                    except ray.exceptions.RayError as err:  # its worker died, or the node it ran on
                        raise JobFailed(names[i], err) from err
                    bar.update(1)
                    if on_result is not None:
                        on_result(i, results[i])
    except BaseException:
        for ref in pending:
            try:
                ray.cancel(ref, force=True)
            except Exception:  # already ended, or the cluster is gone: nothing left to stop
                pass
        disconnect()
        raise
    return results


__all__ = ["CONNECT_TIMEOUT_S", "check_ray_head", "connect", "disconnect", "run_ray"]
