"""``RemoteObservations``: the :class:`~awda_bench.episode.Observations` a served policy is handed;
each call asks the harness over the socket and waits for the answer (see
:mod:`awda_bench.serving.protocol`)."""

from __future__ import annotations

from typing import Any

import numpy as np
from websockets.sync.connection import Connection

from awda_bench.episode import Proprioception, WristDepth
from awda_bench.errors import RemotePolicyError
from awda_bench.serving.protocol import OBSERVATION, OBSERVATION_ERROR, OBSERVE
from awda_bench.serving.wire import pack, unpack

HARNESS = "the harness"
"""How the server names its peer in errors."""


class RemoteObservationError(RuntimeError):
    """The harness could not produce an observation the served policy asked for (its message is
    the harness's error, e.g. ``first_frame()`` asked for after the first step)."""


class RemoteObservations:
    """The observations of the episode the harness is playing, fetched on request."""

    def __init__(self, connection: Connection, num_envs: int) -> None:
        self._connection = connection
        self.num_envs = num_envs

    def _call(self, call: str, **args: Any) -> Any:
        self._connection.send(pack({"type": OBSERVE, "call": call, "args": args}))
        reply = unpack(self._connection.recv(), peer=HARNESS)
        if reply["type"] == OBSERVATION:
            return reply["value"]
        if reply["type"] == OBSERVATION_ERROR:
            raise RemoteObservationError(f"the harness could not give {call}(): {reply['message']}")
        raise RemotePolicyError(
            f"{HARNESS} answered {call}() with a {reply['type']!r} message; check that both "
            "sides run the same awda_bench version"
        )

    def demo_frames(self, count: int = 10) -> np.ndarray:
        return np.asarray(self._call("demo_frames", count=count))

    def first_frame(self) -> np.ndarray:
        return np.asarray(self._call("first_frame"))

    def rgb(self) -> np.ndarray:
        return np.asarray(self._call("rgb"))

    def _record(self, call: str, kind: type) -> Any:
        value = self._call(call)
        if not isinstance(value, kind):
            raise RemotePolicyError(
                f"{HARNESS} answered {call}() with a {type(value).__name__}, not a "
                f"{kind.__name__}; check that both sides run the same awda_bench version"
            )
        return value

    def wrist_depth(self) -> WristDepth:
        return self._record("wrist_depth", WristDepth)

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        intrinsic, extrinsic = self._call("camera")
        return np.asarray(intrinsic), np.asarray(extrinsic)

    def proprio(self) -> Proprioception:
        return self._record("proprio", Proprioception)
