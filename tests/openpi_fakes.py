"""openpi policies (``infer(obs) -> {"actions": ...}``) for testing ``run --method remote
--protocol openpi`` against openpi's own server (``openpi_server.WebsocketPolicyServer``), and a
way to serve one: on a thread (:func:`openpi_serving`) or in a process of its own
(``python tests/openpi_fakes.py NAME PORT``, for a server that dies mid-run).

Their actions follow :func:`fake_action`, a function of the episode's seed and the step, so an
in-process :class:`SeededStepPolicy` plays the same episode and the records can be compared.
"""

from __future__ import annotations

import asyncio
import os
import socket
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from websockets.sync.client import connect

from awda_bench.episode import EpisodeContext

NO_OBSERVATIONS: dict[str, Any] = {"observation_keys": []}
"""Metadata for the fake suite (its env renders nothing): send the episode keys only."""


def fake_action(seed: int, step: int) -> np.ndarray:
    """The action of ``step`` (0-based) of the episode seeded ``seed``: x in [0, 1) varies with
    both (the fake env succeeds when x beats a seed-fixed threshold), y = step (checks order)."""
    x = ((seed * 7 + step * 131) % 1000) / 1000
    return np.array([x, float(step), 0.0, 0.0], np.float32)


class SeededStepPolicy:
    """In-process twin of :class:`ChunkPolicy`: :func:`fake_action` one step at a time."""

    name = "seeded-step"

    def reset(self, ctx: EpisodeContext) -> None:
        self.seed, self.t = ctx.spec.seed, 0

    def act(self, obs: Any) -> np.ndarray:
        action = fake_action(self.seed, self.t)
        self.t += 1
        return action[None]

    done = False
    waypoints = None


class ChunkPolicy:
    """Answers each request with the next ``horizon`` actions of :func:`fake_action` (shape
    ``(4,)`` when ``horizon`` is 0); logs ``(episode_id, step)`` of every request."""

    def __init__(self, horizon: int) -> None:
        self.horizon = horizon
        self.requests: list[tuple[str, int]] = []

    def infer(self, obs: dict) -> dict:
        seed, step = int(obs["episode/seed"]), int(obs["step"])
        self.requests.append((obs["episode_id"], step))
        if self.horizon == 0:
            return {"actions": fake_action(seed, step)}
        return {"actions": np.stack([fake_action(seed, step + i) for i in range(self.horizon)])}

    def reset(self) -> None:
        pass


class MisbehavingPolicy(ChunkPolicy):
    """Task 2: episode 1 raises, 2 answers a (2, 3) chunk, 3 NaN; task 3: episode 1 answers no
    ``actions``, 2 a string, 3 stalls ``stall_s`` at step 2; otherwise :class:`ChunkPolicy`."""

    def __init__(self, stall_s: float = 0.0) -> None:
        super().__init__(horizon=0)
        self.stall_s = stall_s

    def infer(self, obs: dict) -> dict:
        task, episode = int(obs["episode/task"]), int(obs["episode/episode"])
        reply = super().infer(obs)
        if (task, episode) == (2, 1):
            raise RuntimeError("boom in infer")
        if (task, episode) == (2, 2):
            return {"actions": np.zeros((2, 3))}
        if (task, episode) == (2, 3):
            return {"actions": np.full(4, np.nan)}
        if (task, episode) == (3, 1):
            return {"action": reply["actions"]}
        if (task, episode) == (3, 2):
            return {"actions": "forward"}
        if (task, episode) == (3, 3) and int(obs["step"]) == 2:
            time.sleep(self.stall_s)
        return reply


class ExitingPolicy(ChunkPolicy):
    """Kills its server's process at task 2 episode 1 (a crashed server)."""

    def __init__(self) -> None:
        super().__init__(horizon=0)

    def infer(self, obs: dict) -> dict:
        if (int(obs["episode/task"]), int(obs["episode/episode"])) == (2, 1):
            os._exit(7)
        return super().infer(obs)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_until_listening(url: str, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with connect(url, open_timeout=1.0, proxy=None) as connection:
                connection.recv(timeout=5.0)  # the metadata
            return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


@contextmanager
def openpi_serving(policy: Any, metadata: dict | None = None) -> Iterator[str]:
    """``openpi_server.WebsocketPolicyServer(policy, metadata=...)`` on a thread; its URL."""
    from openpi_server import WebsocketPolicyServer

    port = free_port()
    server = WebsocketPolicyServer(policy, host="127.0.0.1", port=port, metadata=metadata)
    loop = asyncio.new_event_loop()
    task = loop.create_task(server.run())

    def run() -> None:
        try:
            loop.run_until_complete(task)
        except asyncio.CancelledError:
            pass  # how it is stopped: the server has no shutdown of its own

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    url = f"ws://127.0.0.1:{port}"
    try:
        wait_until_listening(url)
        yield url
    finally:
        loop.call_soon_threadsafe(task.cancel)
        thread.join(timeout=10)
        loop.close()


if __name__ == "__main__":  # python tests/openpi_fakes.py exiting PORT
    from openpi_server import WebsocketPolicyServer

    name, port = sys.argv[1], int(sys.argv[2])
    policies = {"exiting": ExitingPolicy, "chunk": lambda: ChunkPolicy(0)}
    WebsocketPolicyServer(
        policies[name](), host="127.0.0.1", port=port, metadata=NO_OBSERVATIONS
    ).serve_forever()
