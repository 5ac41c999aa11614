"""``PolicyServer``: a policy behind a websocket, for ``run --method remote`` to evaluate
(``python -m awda_bench serve`` builds one; the conversation is :mod:`.protocol`'s).

Each connection (one per harness worker) plays its episodes on a policy of its own, taken from
an idle pool or built with ``make_policy`` (the first is built before the server listens, so a
method that cannot be built is refused at start-up); a finished connection's policy goes back to
the pool. A policy that raises in ``reset`` or ``act`` answers that request with an ``error``
message (the harness records the episode as an error) and the connection goes on; its traceback
is printed on the server's stderr.
"""

from __future__ import annotations

import sys
import threading
import traceback
from collections.abc import Callable
from dataclasses import fields
from types import TracebackType
from typing import Any

import numpy as np
from websockets.exceptions import ConnectionClosed
from websockets.sync.server import Server, ServerConnection, serve

from awda_bench.episode import EpisodeContext, EpisodeSpec, Policy, seed_globals
from awda_bench.serving.protocol import (
    ACT,
    ACTION,
    ERROR,
    MAX_MESSAGE_BYTES,
    RESET,
    RESET_DONE,
    ServerInfo,
)
from awda_bench.serving.remote_observations import HARNESS, RemoteObservations
from awda_bench.serving.wire import pack, unpack


def _waypoints(policy: Policy) -> np.ndarray | None:
    waypoints = policy.waypoints
    return None if waypoints is None else np.asarray(waypoints, dtype=float)


class _Session:
    """One connection's episodes: the policy, the current episode's observations."""

    def __init__(self, connection: ServerConnection, policy: Policy, info: ServerInfo) -> None:
        self.connection = connection
        self.policy = policy
        self.info = info
        self.observations: RemoteObservations | None = None

    def answer(self, message: dict[str, Any]) -> dict[str, Any]:
        """The reply to one ``reset`` or ``act`` request."""
        kind = message["type"]
        if kind == RESET:
            names = {f.name for f in fields(EpisodeSpec)}
            spec = EpisodeSpec(**{k: v for k, v in message["spec"].items() if k in names})
            self.observations = RemoteObservations(self.connection, int(message["num_envs"]))
            seed_globals(spec.seed)
            ctx = EpisodeContext(
                None, spec, observations=self.observations, method=self.info.method
            )
            self.policy.reset(ctx)
            return {
                "type": RESET_DONE,
                "done": bool(self.policy.done),
                "waypoints": _waypoints(self.policy),
            }
        if kind == ACT:
            if self.observations is None:
                raise RuntimeError("act before the first reset")
            action = np.asarray(self.policy.act(self.observations))
            return {
                "type": ACTION,
                "action": action,
                "done": bool(self.policy.done),
                "waypoints": _waypoints(self.policy),
            }
        raise RuntimeError(f"unexpected {kind!r} request (expected {RESET!r} or {ACT!r})")


class PolicyServer:
    """Serve policies built by ``make_policy`` as ``info`` on ``ws://host:port`` (port 0: any
    free port; :attr:`url` says which)."""

    def __init__(
        self,
        make_policy: Callable[[], Policy],
        info: ServerInfo,
        host: str = "127.0.0.1",
        port: int = 0,
    ) -> None:
        self.info = info
        self._make_policy = make_policy
        self._idle: list[Policy] = [make_policy()]
        self._lock = threading.Lock()
        self._started = False
        self._server: Server = serve(
            self._handle,
            host,
            port,
            compression=None,  # frames are already dense; deflate would cost ~10 ms each
            max_size=MAX_MESSAGE_BYTES,
        )
        bound_host, bound_port = self._server.socket.getsockname()[:2]
        self.url = f"ws://{bound_host}:{bound_port}"
        """The address to give ``run --policy-url``."""

    def _take_policy(self) -> Policy:
        with self._lock:
            if self._idle:
                return self._idle.pop()
        return self._make_policy()

    def _give_back(self, policy: Policy) -> None:
        """A finished connection's policy, back to the idle pool."""
        with self._lock:
            self._idle.append(policy)

    def _handle(self, connection: ServerConnection) -> None:
        policy = self._take_policy()
        session = _Session(connection, policy, self.info)
        try:
            connection.send(pack(self.info.to_message()))
            for data in connection:
                message = unpack(data, peer=HARNESS)
                try:
                    reply = session.answer(message)
                    encoded = pack(reply)
                except ConnectionClosed:
                    raise
                except Exception as exc:  # the policy's error goes to the harness, and the log
                    print(
                        f"served policy {self.info.method!r} raised:\n{traceback.format_exc()}",
                        file=sys.stderr,
                        flush=True,
                    )
                    text = " ".join(f"{type(exc).__name__}: {exc}".split())
                    encoded = pack({"type": ERROR, "message": text})
                connection.send(encoded)
        except ConnectionClosed:
            pass  # the harness went away (finished, killed, or timed out): nothing to answer
        finally:
            self._give_back(policy)

    def serve_forever(self) -> None:
        """Serve until :meth:`shutdown` (or the process ends)."""
        self._started = True
        self._server.serve_forever()

    def shutdown(self) -> None:
        """Stop listening, close the connections and wait for their handlers."""
        if self._started:
            self._server.shutdown()
        else:  # never served: websockets' shutdown would wait for serve_forever to end
            self._server.socket.close()

    def __enter__(self) -> PolicyServer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.shutdown()
