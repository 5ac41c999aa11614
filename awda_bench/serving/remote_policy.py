"""``RemotePolicy``: the harness's side of a served policy (``run --method remote``), a
:class:`~awda_bench.episode.Policy` whose ``reset`` and ``act`` are played by a policy server
(:mod:`.protocol`), answering its observation requests from the episode's own observations.

Every failure is a one-line :class:`~awda_bench.errors.RemotePolicyError` naming the problem and
the fix; inside an episode the harness records it as that episode's error, so re-running the
same command retries it. After a timeout, a dropped connection or a message out of turn the
connection is closed, and the next episode connects afresh (a restarted server is picked up).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection

from awda_bench.episode import EpisodeContext, Observations, observations_of
from awda_bench.errors import RemotePolicyError
from awda_bench.serving.connection import (
    DEFAULT_TIMEOUT_S,
    lost_connection,
    open_with_greeting,
    receive,
    server_peer,
)
from awda_bench.serving.protocol import (
    ACT,
    ACTION,
    ERROR,
    HELLO,
    NATIVE,
    OBSERVATION,
    OBSERVATION_CALLS,
    OBSERVATION_ERROR,
    OBSERVE,
    PROTOCOL,
    RESET,
    RESET_DONE,
    ServerInfo,
)
from awda_bench.serving.wire import NOT_OURS, decode, pack, unpack

START_HINT = "`python -m awda_bench serve --method ... --port PORT`"
"""How errors say to start a native server."""

ACTION_DIM = 4
"""dx, dy, dz, grip."""


@dataclass(frozen=True)
class ServedMethod:
    """Where a served method is and what it serves (fixed when the run is planned)."""

    url: str
    """``ws://HOST:PORT`` of the server."""
    info: ServerInfo
    """The server's ``hello`` at planning time; a worker refuses a server that now serves
    another method or snapshot."""
    timeout_s: float = DEFAULT_TIMEOUT_S
    """Longest wait for one message [s]."""
    protocol: str = NATIVE
    """What the server speaks: :data:`~.protocol.NATIVE` (``awda-policy/1``, played by
    :class:`RemotePolicy`) or :data:`~.protocol.OPENPI` (played by
    :class:`~.openpi_policy.OpenpiPolicy`)."""


def _open(url: str, timeout_s: float) -> tuple[ClientConnection, ServerInfo]:
    """Connect and read the server's hello."""
    peer = server_peer(url)
    connection, data = open_with_greeting(
        url,
        timeout_s,
        START_HINT,
        silence="said nothing",
        hint="is it `python -m awda_bench serve`?",
    )
    try:
        hello = decode(data, peer=peer, hint=NOT_OURS) if isinstance(data, bytes) else None
    except RemotePolicyError:
        connection.close()
        raise
    if not isinstance(hello, dict) or "type" not in hello:
        connection.close()
        raise RemotePolicyError(
            f"{peer} does not speak {PROTOCOL} (its first message is not a hello); for an openpi "
            "policy server give --protocol openpi"
        )
    if hello.get("type") != HELLO or hello.get("protocol") != PROTOCOL:
        connection.close()
        raise RemotePolicyError(
            f"{peer} speaks {hello.get('protocol')!r}, this harness {PROTOCOL!r}; run the same "
            "awda_bench version on both sides (or, for an openpi server, give --protocol openpi)"
        )
    return connection, ServerInfo.from_message(hello)


def fetch_server_info(url: str, timeout_s: float = DEFAULT_TIMEOUT_S) -> ServerInfo:
    """What the server at ``url`` serves (connects, reads its hello, disconnects)."""
    connection, info = _open(url, timeout_s)
    connection.close()
    return info


def check_actions(
    action: Any, peer: str, accept: Callable[[tuple[int, ...]], bool], expected: str
) -> np.ndarray:
    """``action`` if it is a finite numeric array whose shape ``accept`` takes, else a one-line
    error (``expected`` names the shapes taken)."""
    if not isinstance(action, np.ndarray) or action.dtype.kind not in "iuf":
        raise RemotePolicyError(
            f"{peer} returned a {type(action).__name__} as the action, not a numeric array; "
            f"the served policy must return a {expected} float array"
        )
    if not accept(action.shape):
        raise RemotePolicyError(
            f"{peer} returned an action of shape {action.shape}, expected {expected}; fix the "
            "served policy"
        )
    if not np.isfinite(action).all():
        raise RemotePolicyError(
            f"{peer} returned an action with NaN or inf ({action.tolist()}); fix the served policy"
        )
    return action


def check_action(action: Any, num_envs: int, peer: str) -> np.ndarray:
    """``action`` if it is a finite ``(num_envs, 4)`` numeric array, else a one-line error."""
    shape = (num_envs, ACTION_DIM)
    return check_actions(action, peer, lambda s: s == shape, f"{shape} (dx, dy, dz, grip per env)")


def check_still_served(
    connection: ClientConnection, info: ServerInfo, expected: ServerInfo, peer: str
) -> None:
    """Close ``connection`` and refuse in one line when the server at ``peer`` now serves another
    method or snapshot than the run evaluates (``expected``); either protocol's reconnect."""
    if (info.method, info.snapshot) != (expected.method, expected.snapshot):
        connection.close()
        raise RemotePolicyError(
            f"{peer} now serves {info.method!r} snapshot {info.snapshot_name} "
            f"({info.snapshot}); this run evaluates {expected.method!r} snapshot "
            f"{expected.snapshot_name} ({expected.snapshot}): serve that again, or start a "
            "new run"
        )


class ServedPolicyClient:
    """The harness's side of a served policy in either protocol (:class:`RemotePolicy`,
    :class:`~.openpi_policy.OpenpiPolicy`): the served method, its name in the store, the
    connection (opened when first needed by the protocol's :meth:`_connect`) and the waypoints
    the server last sent."""

    privileged = False

    def __init__(self, served: ServedMethod, name: str | None = None) -> None:
        self.served = served
        self.name = name or served.info.method
        self._peer = server_peer(served.url)
        self._connection: ClientConnection | None = None
        self._waypoints: np.ndarray | None = None

    def _connect(self) -> ClientConnection:
        """A new connection to the server, refused unless it still serves ``served.info``."""
        raise NotImplementedError

    def _open_connection(self) -> ClientConnection:
        """The connection, opened with :meth:`_connect` when there is none."""
        if self._connection is None:
            self._connection = self._connect()
        return self._connection

    def close(self) -> None:
        """Close the connection (the next request opens a new one)."""
        if self._connection is not None:
            self._connection.close()
            self._connection = None

    @property
    def waypoints(self) -> np.ndarray | None:
        return self._waypoints


class RemotePolicy(ServedPolicyClient):
    """A policy played by the server at ``served.url``; named ``name`` in the store."""

    def __init__(self, served: ServedMethod, name: str | None = None) -> None:
        super().__init__(served, name)
        self._observations: Observations | None = None
        self._done = False
        self._step = 0

    # ------------------------------------------------------------------ connection
    def _connect(self) -> ClientConnection:
        connection, info = _open(self.served.url, self.served.timeout_s)
        check_still_served(connection, info, self.served.info, self._peer)
        return connection

    # ------------------------------------------------------------------ exchanges
    def _answer(self, connection: ClientConnection, request: dict[str, Any]) -> None:
        """Answer one ``observe`` request from the episode's observations."""
        call = request.get("call")
        if call not in OBSERVATION_CALLS or self._observations is None:
            reply = {
                "type": OBSERVATION_ERROR,
                "message": f"{call!r} is not an observation; ask for one of "
                f"{', '.join(OBSERVATION_CALLS)}",
            }
        else:
            args = {
                k: v for k, v in request.get("args", {}).items() if k in OBSERVATION_CALLS[call]
            }
            try:
                value = getattr(self._observations, call)(**args)
                reply = {"type": OBSERVATION, "value": value}
            except Exception as exc:  # the served policy sees it raised from its own call
                reply = {"type": OBSERVATION_ERROR, "message": f"{type(exc).__name__}: {exc}"}
        connection.send(pack(reply))

    def _exchange(self, message: dict[str, Any], expect: str, during: str) -> dict[str, Any]:
        """Send ``message``, answer observation requests, return the ``expect`` reply."""
        connection = self._open_connection()
        try:
            connection.send(pack(message))
            while True:
                data = receive(connection, self.served.timeout_s, self._peer, during)
                reply = unpack(data, peer=self._peer)
                if reply["type"] == OBSERVE:
                    self._answer(connection, reply)
                elif reply["type"] == expect:
                    self._done = bool(reply.get("done", False))
                    waypoints = reply.get("waypoints")
                    self._waypoints = None if waypoints is None else np.asarray(waypoints)
                    return reply
                elif reply["type"] == ERROR:
                    raise _ServedPolicyRaised(
                        f"the served policy raised during {during}: {reply.get('message')} "
                        "(traceback in the server's log)"
                    )
                else:
                    raise RemotePolicyError(
                        f"{self._peer} sent {reply['type']!r} during {during}, expected "
                        f"{expect!r}; run the same awda_bench version on both sides"
                    )
        except _ServedPolicyRaised:
            raise  # the conversation is in step: keep the connection
        except ConnectionClosed as exc:
            self.close()
            raise lost_connection(self._peer, during, exc) from exc
        except BaseException:
            self.close()  # out of step (timeout, bad message): the next episode reconnects
            raise

    # ------------------------------------------------------------------ Policy
    def reset(self, ctx: EpisodeContext) -> None:
        self._observations = observations_of(ctx)
        self._done, self._waypoints = False, None
        self._step = 0
        self._exchange(
            {
                "type": RESET,
                "spec": asdict(ctx.spec),
                "num_envs": int(self._observations.num_envs),
            },
            expect=RESET_DONE,
            during=f"reset (task {ctx.spec.task}, episode {ctx.spec.episode})",
        )

    def act(self, obs: Any) -> np.ndarray:
        if self._observations is None:
            raise RuntimeError("act before reset")
        self._step += 1
        reply = self._exchange({"type": ACT}, expect=ACTION, during=f"step {self._step}")
        return check_action(reply.get("action"), int(self._observations.num_envs), self._peer)

    @property
    def done(self) -> bool:
        return self._done


class _ServedPolicyRaised(RemotePolicyError):
    """The served policy raised; the server answered in turn, so the connection stays usable."""
