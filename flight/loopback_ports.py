"""Free loopback ports, for the demo, the benches and the tests that open real sockets on
127.0.0.1 (never a non-loopback address)."""

from __future__ import annotations

import socket

__all__ = ["free_tcp_port", "free_udp_port"]


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing is bound to right now."""
    return _free_port(socket.SOCK_DGRAM)


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    return _free_port(socket.SOCK_STREAM)
