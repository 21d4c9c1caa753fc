"""Built-in executor plugins: where the runs of ``explore compare`` execute.

An executor has one method, ``run(specs, on_done)``: execute every
:class:`explore.runtime.compare.RunSpec` (each in its own process, see
:class:`explore.runtime.compare.IsolatedRun`) and call ``on_done(spec, row)`` in the calling thread
as each run ends. Both built-ins start the very same worker command with the same
environment, so the same seeds give the same results on either.
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from explore.api import Executor
from explore.core import BadInput, Param, captured_output, check_path_name
from explore.runtime import OnDone, RunSpec, run_isolated, run_local


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


class LocalExecutor(Executor):
    """Local process pool: every run in its own process, ``jobs`` at a time (0 = the cores)."""

    name = "local"
    params = (Param("jobs", int, 0, "", "concurrent runs (0: one per core)", low=0),)

    def __init__(self, jobs: int = 0) -> None:
        self.jobs = jobs or _cores()

    def run(self, specs: Sequence[RunSpec], on_done: OnDone) -> None:
        run_local(specs, on_done, self.jobs)


def _ray_token_given() -> bool:
    """Whether the driver has a Ray auth token, where Ray looks for one (its own precedence)."""
    return bool(os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH")
                or (Path.home() / ".ray" / "auth_token").is_file())


def _token_mode() -> None:
    """Connect in Ray's token mode. Ray reads ``RAY_AUTH_MODE`` when it is imported, so a Ray
    imported earlier in this process is told again (its own refresh, as ``ray.init`` does)."""
    os.environ.setdefault("RAY_AUTH_MODE", "token")
    if "ray" in sys.modules:
        with contextlib.suppress(ImportError, AttributeError):
            from ray._private.authentication.authentication_token_setup import _enable_token_auth
            from ray._raylet import AuthenticationTokenLoader

            _enable_token_auth()
            AuthenticationTokenLoader.instance().reset_cache()


def _reach(address: str, timeout: float = 5.0) -> None:
    """Fail at once (one line) when nothing listens at ``HOST:PORT``: ``ray.init`` would retry for minutes."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise BadInput("--ray-address", address, "expected HOST:PORT, ray://HOST:PORT or auto")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as error:
        raise BadInput("--ray-address", address, f"no Ray head answers there ({error.strerror or error})") from None


class RayExecutor(Executor):
    """Ray tasks: the runs on a Ray cluster (``address``) or a local Ray instance (``jobs`` CPUs).

    Each task starts the run's process on its node, so ``--out`` must be a folder that every
    node can write (a shared file system); the rows travel back to the driver either way.

    A cluster started with token authentication (``RAY_AUTH_MODE=token``, the default of new
    Ray releases) needs its token on the driver: ``token_file`` (``--ray-token-file``), or
    Ray's own ``RAY_AUTH_TOKEN`` / ``RAY_AUTH_TOKEN_PATH`` / ``~/.ray/auth_token``. With a
    token the driver connects in token mode (which a cluster without authentication accepts too).
    """

    name = "ray"
    params = (
        Param("address", str, "", "", "Ray cluster address HOST:PORT (empty: start a local instance)"),
        Param("jobs", int, 0, "", "CPUs of a local instance (0: one per core)", low=0),
        Param("token_file", str, "", "", "file holding the cluster's auth token (else Ray's RAY_AUTH_TOKEN, "
              "RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token)"),
    )

    def __init__(self, address: str = "", jobs: int = 0, token_file: str = "") -> None:
        self.address = address
        self.jobs = jobs or _cores()
        self.token_file = token_file
        self._started_here = False

    def check(self) -> None:
        """Connect before any run starts: an unreachable head or a refused token is one line (exit 2)."""
        options: dict[str, Any] = {"log_to_driver": False, "configure_logging": False}
        if self.token_file:
            token = check_path_name(self.token_file, "--ray-token-file")
            if not token.is_file() or not token.read_text(encoding="utf-8", errors="replace").strip():
                raise BadInput("--ray-token-file", self.token_file, "no such file, or it is empty")
            os.environ["RAY_AUTH_TOKEN_PATH"] = str(token.resolve())
        if not self.address:
            import ray

            if not ray.is_initialized():
                with captured_output():
                    ray.init(num_cpus=self.jobs, include_dashboard=False, **options)
                self._started_here = True
            return
        if self.address != "auto":
            _reach(self.address)
        if _ray_token_given():
            _token_mode()
        import ray

        if ray.is_initialized():
            return
        with captured_output() as printed:
            try:
                ray.init(address=self.address, **options)
            except (ConnectionError, RuntimeError, ray.exceptions.AuthenticationError) as error:
                failure = error
            else:
                failure = None
        if failure is not None:
            if "InvalidAuthToken" in printed.text or "Unauthenticated" in printed.text:
                why = ("the cluster uses token authentication and refused this driver's token" if _ray_token_given()
                       else "the cluster uses token authentication: give its token with --ray-token-file "
                       "(or RAY_AUTH_TOKEN / RAY_AUTH_TOKEN_PATH)")
            else:
                why = f"could not join the Ray cluster ({type(failure).__name__}: {str(failure).splitlines()[0]})"
            raise BadInput("--ray-address", self.address, why)
        self._started_here = True

    def run(self, specs: Sequence[RunSpec], on_done: OnDone) -> None:
        import ray

        self.check()
        task = ray.remote(num_cpus=1, max_retries=0)(run_isolated)
        refs = {task.remote(spec.to_dict()): spec for spec in specs}
        try:
            while refs:
                done, _ = ray.wait(list(refs), num_returns=1)
                for ref in done:
                    spec = refs.pop(ref)
                    try:
                        row = ray.get(ref)
                    except Exception as error:  # noqa: BLE001 - a lost task is a crashed run
                        row = {**spec.grid_values(), "status": "crashed", "reason": f"ray: {type(error).__name__}"}
                    on_done(spec, row)
        finally:
            for ref in refs:
                ray.cancel(ref, force=True)
            if self._started_here:
                ray.shutdown()
                self._started_here = False


PLUGINS: list = [LocalExecutor, RayExecutor]
