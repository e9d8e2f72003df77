"""A Dask cluster for work that splits into independent tasks (the twin's
campaign positions, discovery's benchmark runs): a client of a scheduler
whose workers can each do the work, or one readable line why not."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from distributed import Client

# Long enough for a scheduler across a network, short enough for a typo.
CONNECT_TIMEOUT_S = 5


class ClusterError(RuntimeError):
    """A scheduler that cannot be used; one readable line."""


@contextmanager
def connect_cluster(address: str, worker_problem: Callable[[], str | None], work: str) -> Iterator[Client]:
    """A client of the Dask scheduler at ``address`` with at least one
    worker, each of which ``worker_problem`` (run there) finds able to do
    the work: it returns None, or why not. ``work`` names the work in the
    error ("run the twin")."""
    try:
        from distributed import Client
        from distributed.comm import get_address_host_port
    except ImportError:
        raise ClusterError(
            "--scheduler needs Dask's distributed package: "
            "pip install -r host/requirements.txt (or the thermotilt[dask] extra)"
        ) from None
    try:
        get_address_host_port(address)
    except ValueError as error:
        raise ClusterError(f"--scheduler {address}: {error}; give one like tcp://HOST:8786") from None
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as error:
        raise ClusterError(f"cannot reach the Dask scheduler at {address}: {error}") from None
    with client:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except TimeoutError:
            raise ClusterError(
                f"the Dask scheduler at {address} has no workers after {CONNECT_TIMEOUT_S} s; "
                f"start `dask worker {address}` on each machine"
            ) from None
        for worker, problem in client.run(worker_problem, on_error="return").items():
            if problem is not None:
                raise ClusterError(f"Dask worker {worker} cannot {work}: {problem}")
        yield client
