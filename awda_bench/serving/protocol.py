"""The conversation between the harness (client) and a policy server, one websocket per worker.

::

    client (a worker's RemotePolicy)              server (python -m awda_bench serve)
      connect ------------------------------->
              <------------------------------   hello   {protocol, method, snapshot, ...}
      reset   {spec, num_envs} --------------->   seed globals with spec.seed; policy.reset(ctx)
              <------------------------------   observe {call, args}      (0 or more times:
      observation {value} -------------------->                            what the policy asks)
              <------------------------------   reset_done {done, waypoints}
      act ------------------------------------>   policy.act(obs)
              <------------------------------   observe {call, args} ... observation {value}
              <------------------------------   action {action, done, waypoints}
      ... act every control step; reset at the next episode, on the same connection
              <------------------------------   error {message}  instead of a reply, when
                                                the policy raised (the episode is an error)

Observations are rendered on request in this project (``ctx.observations``, ~50 ms a frame), so
nothing is sent ahead: every :class:`~awda_bench.episode.Observations` call the served policy
makes (``demo_frames``, ``first_frame``, ``rgb``, ``wrist_depth``, ``camera``, ``proprio``)
becomes one ``observe`` request that the client answers from the episode's own observations.
The served policy therefore sees exactly what an in-process one sees, rendered in the same order,
and an episode's record is the same (``tests/test_serve.py``); a policy that reads nothing (as
``random``) costs one round trip per step.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

PROTOCOL = "awda-policy/1"
"""Name and version of this conversation; the client refuses a server speaking another."""

NATIVE = "awda"
"""``--protocol awda`` (the default): this conversation."""
OPENPI = "openpi"
"""``--protocol openpi``: openpi's websocket policy protocol (:mod:`.openpi_schema`)."""
PROTOCOLS = (NATIVE, OPENPI)
"""The ``--protocol`` choices of ``serve`` and ``run --method remote``."""

MAX_MESSAGE_BYTES = 256 * 1024 * 1024
"""Largest message either side accepts (ten demo frames are 2.3 MB)."""

HELLO = "hello"
RESET = "reset"
RESET_DONE = "reset_done"
ACT = "act"
ACTION = "action"
OBSERVE = "observe"
OBSERVATION = "observation"
OBSERVATION_ERROR = "observation_error"
"""The client could not produce an observation (the call raised); the server's policy sees the
error raised from its ``Observations`` call."""
ERROR = "error"

OBSERVATION_CALLS: dict[str, tuple[str, ...]] = {
    "demo_frames": ("count",),
    "first_frame": (),
    "rgb": (),
    "wrist_depth": (),
    "camera": (),
    "proprio": (),
}
"""The :class:`~awda_bench.episode.Observations` methods a server may call, with their keyword
arguments; the client answers nothing else."""


@dataclass(frozen=True)
class ServerInfo:
    """What a server says it serves (its ``hello``); the harness labels the rows with it."""

    method: str
    """The served method's name, as ``run --method`` would name it in-process."""
    snapshot: str
    """The served snapshot's content hash (``"builtin"`` for a non-learned method)."""
    snapshot_name: str
    """The snapshot's file name (``"builtin"``)."""
    snapshot_order: int
    """The snapshot's position in its method's training order (0 for non-learned)."""
    learned: bool
    """The method is evaluated per snapshot."""
    protocol: str = PROTOCOL
    """:data:`PROTOCOL` of the server."""

    def to_message(self) -> dict[str, Any]:
        return {"type": HELLO, **asdict(self)}

    @classmethod
    def from_message(cls, message: dict[str, Any]) -> ServerInfo:
        fields = {k: message[k] for k in cls.__dataclass_fields__ if k in message}
        return cls(**fields)
