"""Where the live view is served: ``[HOST:]PORT`` as the command line gives
it. Imports nothing heavy, so a bad address is answered before Starlette loads."""

from __future__ import annotations

import errno
import socket
from dataclasses import dataclass

from ..options import UsageError

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


@dataclass(frozen=True)
class Address:
    host: str
    port: int

    def url(self, port: int | None = None) -> str:
        """The page's URL; port, the one bound, when the address asked for any (0)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port if port is None else port}/"


def parse_address(text: str) -> Address:
    """[HOST:]PORT (an IPv6 host in brackets), the host DEFAULT_HOST when
    not given; UsageError, one line, for anything else."""
    host, colon, port_text = text.strip().rpartition(":")
    host = host.strip("[]") if colon else DEFAULT_HOST
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not host or not 0 <= port <= 65535:
        raise UsageError(f"--serve {text!r}: expected [HOST:]PORT, e.g. 8765 or 127.0.0.1:8765 (port 0 to 65535)")
    return Address(host, port)


def bind(address: Address) -> socket.socket:
    """A listening socket at address; UsageError, one line, for a port in
    use, a host this machine is not, or a name that does not resolve."""
    family = socket.AF_INET6 if ":" in address.host else socket.AF_INET
    try:
        return socket.create_server((address.host, address.port), family=family)
    except OSError as error:
        if error.errno == errno.EADDRINUSE:
            why = "the port is in use (give another with --serve [HOST:]PORT)"
        else:
            why = error.strerror or str(error)
        raise UsageError(f"cannot serve the live view on {address.host}:{address.port}: {why}") from None
