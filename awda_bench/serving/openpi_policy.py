"""``OpenpiPolicy``: the harness as an openpi client (``run --method remote --protocol openpi``),
a :class:`~awda_bench.episode.Policy` played by any server speaking openpi's websocket policy
protocol (the observation dict, the reply and the metadata are :mod:`.openpi_schema`'s).

An episode's first request goes out in ``reset`` (step 0, with the demonstration); its reply's
actions are played one per ``act``, and the next request goes out when they are used up (or
after the metadata's ``action_horizon`` of them), like openpi's ``ActionChunkBroker``. The episode
ends at the suite's horizon or once the actions of a reply saying ``done`` are played.

Failures are the native protocol's (:mod:`.remote_policy`), one line each, recorded as that
episode's error: a server that cannot be reached, no reply within ``--policy-timeout``, a dropped
connection, a traceback text frame (the served policy raised; openpi's server then closes the
connection), a reply without ``actions``, actions that are not a finite ``(4,)`` or ``(H, 4)``
array, or a server that now serves another method or snapshot than the run planned. After any of
them but a bad reply, the connection is closed and the next episode connects afresh.

What the server said about each episode (its metadata, the number of requests and its
``server_timing``, mean and max per key) is :attr:`OpenpiPolicy.server_notes`, stored beside the
episode's row (the ``server`` column).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection

from awda_bench.episode import EpisodeContext, EpisodeSpec, Observations, observations_of
from awda_bench.errors import RemotePolicyError
from awda_bench.serving.connection import (
    lost_connection,
    open_with_greeting,
    receive,
    server_peer,
)
from awda_bench.serving.openpi_schema import (
    ACTIONS,
    DONE,
    SERVER_TIMING,
    WAYPOINTS,
    OpenpiOptions,
    jsonable,
    observation_request,
    server_info,
)
from awda_bench.serving.protocol import OPENPI, PROTOCOL, ServerInfo
from awda_bench.serving.remote_policy import (
    ACTION_DIM,
    ServedMethod,
    ServedPolicyClient,
    check_actions,
    check_still_served,
)
from awda_bench.serving.wire import decode, pack_openpi

START_HINT = (
    "your openpi policy server (or `python -m awda_bench serve --protocol openpi --method ...`)"
)
"""How errors say to start an openpi server."""
NOT_OPENPI = "is it an openpi policy server?"


def _open(url: str, timeout_s: float) -> tuple[ClientConnection, dict[str, Any], ServerInfo]:
    """Connect and read the server's metadata."""
    peer = server_peer(url)
    connection, data = open_with_greeting(
        url, timeout_s, START_HINT, silence="sent no metadata", hint=NOT_OPENPI
    )
    try:
        if isinstance(data, str):
            last = (data.strip().splitlines() or [""])[-1].strip()
            raise RemotePolicyError(
                f"{peer} sent text instead of its metadata ({last!r}); {NOT_OPENPI}"
            )
        metadata = decode(data, peer=peer, hint=NOT_OPENPI)
        info = server_info(metadata, peer)
        if metadata.get("type") == "hello" and metadata.get("protocol") == PROTOCOL:
            raise RemotePolicyError(
                f"{peer} speaks awda_bench's own protocol ({PROTOCOL}); drop --protocol openpi"
            )
        OpenpiOptions.from_metadata(metadata, peer)  # refused now, not in every episode
    except BaseException:
        connection.close()
        raise
    return connection, metadata, info


def fetch_openpi_metadata(url: str, timeout_s: float) -> tuple[ServerInfo, dict[str, Any]]:
    """What the openpi server at ``url`` serves and its metadata (connects, reads, disconnects)."""
    connection, metadata, info = _open(url, timeout_s)
    connection.close()
    return info, metadata


def _is_action_shape(shape: tuple[int, ...]) -> bool:
    return shape == (ACTION_DIM,) or (len(shape) == 2 and shape[1] == ACTION_DIM)


class OpenpiPolicy(ServedPolicyClient):
    """A policy played by the openpi server at ``served.url``; named ``name`` in the store."""

    def __init__(self, served: ServedMethod, name: str | None = None) -> None:
        super().__init__(served, name)
        self._metadata: dict[str, Any] = {}
        self._options = OpenpiOptions()
        self._observations: Observations | None = None
        self._spec: EpisodeSpec | None = None
        self._step = 0
        self._chunk: list[np.ndarray] = []
        self._server_done = False
        self._requests = 0
        self._timing: dict[str, list[float]] = {}

    # ------------------------------------------------------------------ connection
    def _connect(self) -> ClientConnection:
        connection, metadata, info = _open(self.served.url, self.served.timeout_s)
        check_still_served(connection, info, self.served.info, self._peer)
        self._metadata = metadata
        self._options = OpenpiOptions.from_metadata(metadata, self._peer)
        return connection

    # ------------------------------------------------------------------ requests
    def _exchange(self, during: str) -> dict[str, Any]:
        """Send the request for the current step; the server's reply."""
        connection = self._open_connection()
        assert self._observations is not None and self._spec is not None
        request = observation_request(self._observations, self._spec, self._step, self._options)
        try:
            connection.send(pack_openpi(request))
            data = receive(connection, self.served.timeout_s, self._peer, during)
        except ConnectionClosed as exc:
            self.close()
            raise lost_connection(self._peer, during, exc) from exc
        except BaseException:
            self.close()  # out of step (a timeout): the next episode reconnects
            raise
        if isinstance(data, str):  # openpi's server sends its traceback, then closes
            self.close()
            lines = [line.strip() for line in data.strip().splitlines() if line.strip()]
            raise RemotePolicyError(
                f"the served policy raised during {during}: {lines[-1] if lines else '(empty)'} "
                "(traceback in the server's text frame and log)"
            )
        reply = decode(data, peer=self._peer, hint=NOT_OPENPI)
        if not isinstance(reply, dict) or ACTIONS not in reply:
            keys = sorted(map(str, reply)) if isinstance(reply, dict) else type(reply).__name__
            raise RemotePolicyError(
                f"{self._peer} replied without {ACTIONS!r} during {during} (got {keys}); an "
                "openpi policy's infer must return {'actions': (4,) or (H, 4) array}"
            )
        return reply

    def _query(self, during: str) -> None:
        """Ask for the next actions: the chunk to play, done, waypoints, timing."""
        reply = self._exchange(during)
        actions = check_actions(reply[ACTIONS], self._peer, _is_action_shape, "(4,) or (H, 4)")
        chunk = actions.reshape(-1, ACTION_DIM)
        if self._options.action_horizon is not None:
            chunk = chunk[: self._options.action_horizon]
        done = bool(reply.get(DONE, False))
        if len(chunk) == 0 and not done:
            raise RemotePolicyError(
                f"{self._peer} returned no actions (shape {actions.shape}) during {during} "
                "without done; return at least one action"
            )
        self._chunk, self._server_done = list(chunk), done
        waypoints = reply.get(WAYPOINTS)
        self._waypoints = None if waypoints is None else np.asarray(waypoints, dtype=float)
        self._requests += 1
        timing = reply.get(SERVER_TIMING)
        if isinstance(timing, dict):
            for key, value in timing.items():
                if isinstance(value, int | float | np.number) and not isinstance(value, bool):
                    name = key.decode() if isinstance(key, bytes) else str(key)
                    self._timing.setdefault(name, []).append(float(value))

    # ------------------------------------------------------------------ Policy
    def reset(self, ctx: EpisodeContext) -> None:
        observations = observations_of(ctx)
        if int(observations.num_envs) != 1:
            raise RemotePolicyError(
                f"openpi's protocol carries one robot; this episode has {observations.num_envs} "
                "envs"
            )
        self._observations, self._spec = observations, ctx.spec
        self._step, self._chunk, self._server_done, self._waypoints = 0, [], False, None
        self._requests, self._timing = 0, {}
        self._query(f"step 1 (task {ctx.spec.task}, episode {ctx.spec.episode}'s first request)")

    def act(self, obs: Any) -> np.ndarray:
        if self._observations is None:
            raise RuntimeError("act before reset")
        if not self._chunk:
            if self._server_done:
                raise RuntimeError("act after the server said done")
            self._query(f"step {self._step + 1}")
        action = self._chunk.pop(0)
        self._step += 1
        return action[None]

    @property
    def done(self) -> bool:
        return self._server_done and not self._chunk

    @property
    def server_notes(self) -> dict[str, Any]:
        """What the server said about the episode: protocol, metadata, requests made and
        ``server_timing`` per key (mean, max over the requests that reported it) [ms]."""
        return {
            "protocol": OPENPI,
            "metadata": jsonable(self._metadata),
            "requests": self._requests,
            "server_timing": {
                key: {"mean": float(np.mean(values)), "max": float(np.max(values))}
                for key, values in sorted(self._timing.items())
            },
        }
