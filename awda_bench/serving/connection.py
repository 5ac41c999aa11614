"""The harness's connection to a policy server, whichever protocol it speaks: opening it and
waiting on it, with every failure (bad address, nothing listening, no message in time, a dropped
connection) a one-line :class:`~awda_bench.errors.RemotePolicyError` naming the problem and the
fix. :mod:`.remote_policy` (``awda-policy/1``) and :mod:`.openpi_policy` (openpi's protocol) both
talk through these."""

from __future__ import annotations

from contextlib import ExitStack

from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection, connect

from awda_bench.errors import RemotePolicyError
from awda_bench.serving.protocol import MAX_MESSAGE_BYTES

DEFAULT_TIMEOUT_S = 60.0
"""How long the harness waits for any one message from the server [s]."""


def server_peer(url: str) -> str:
    """How errors name the server at ``url``."""
    return f"the policy server at {url}"


def open_connection(url: str, timeout_s: float, start_hint: str) -> ClientConnection:
    """A connection to ``url`` (the caller closes it); ``start_hint`` tells how to start the
    server when nothing answers."""
    try:
        with ExitStack() as stack:  # websockets 17 wants connect() entered as a context
            connection = stack.enter_context(
                connect(
                    url,
                    open_timeout=timeout_s,
                    compression=None,
                    max_size=MAX_MESSAGE_BYTES,
                    proxy=None,
                )
            )
            stack.pop_all()  # the caller closes it
    except InvalidURI as exc:
        raise RemotePolicyError(f"--policy-url {url!r} is not a ws://HOST:PORT address") from exc
    except (OSError, TimeoutError, InvalidHandshake) as exc:
        raise RemotePolicyError(
            f"cannot reach {server_peer(url)} ({type(exc).__name__}: {exc}); start it with "
            f"{start_hint} or fix --policy-url"
        ) from exc
    return connection


def open_with_greeting(
    url: str, timeout_s: float, start_hint: str, *, silence: str, hint: str
) -> tuple[ClientConnection, bytes | str]:
    """A connection to ``url`` (the caller closes it) and the first message its server sends (a
    hello, metadata). When the server hangs up or sends nothing within ``timeout_s`` the
    connection is closed and the error says the server accepted it but ``silence`` (``"said
    nothing"``, ...), then ``hint``."""
    connection = open_connection(url, timeout_s, start_hint)
    try:
        return connection, connection.recv(timeout=timeout_s)
    except (TimeoutError, ConnectionClosed) as exc:
        connection.close()
        raise RemotePolicyError(
            f"{server_peer(url)} accepted the connection but {silence} ({type(exc).__name__}); "
            f"{hint}"
        ) from exc


def receive(connection: ClientConnection, timeout_s: float, peer: str, during: str) -> bytes | str:
    """The next message from ``peer``; waiting longer than ``timeout_s`` is an error."""
    try:
        return connection.recv(timeout=timeout_s)
    except TimeoutError as exc:
        raise RemotePolicyError(
            f"{peer} sent nothing for {timeout_s:g} s during {during}; if the policy is slow "
            "raise --policy-timeout, else check the server's log"
        ) from exc


def lost_connection(peer: str, during: str, exc: ConnectionClosed) -> RemotePolicyError:
    """The error of a connection that dropped during ``during``."""
    return RemotePolicyError(
        f"lost the connection to {peer} during {during} ({exc}); restart the server and re-run "
        "the same command (this episode is recorded as an error and retried)"
    )
