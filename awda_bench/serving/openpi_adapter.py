"""``OpenpiAdapter``: an awda_bench :class:`~awda_bench.episode.Policy` (observation-only) as an
openpi policy, ``infer(obs) -> {"actions": ...}``, for any openpi server to serve: ``serve
--protocol openpi`` (:mod:`.openpi_server`) or openpi's own ``WebsocketPolicyServer``::

    from openpi_server import WebsocketPolicyServer
    adapter = OpenpiAdapter(MyPolicy(), method="mine")
    WebsocketPolicyServer(adapter, port=8000, metadata=adapter.metadata).serve_forever()

The request dicts are :mod:`.openpi_schema`'s. A request with a new ``episode_id`` (or step 0)
starts an episode: the globals are seeded with its seed and ``policy.reset(ctx)`` is called,
``ctx.observations`` reading that request and the ones after it; then every request is one
``policy.act``, answered with its action (``actions`` (4,)), ``done`` and the policy's
``waypoints``. A request out of step (not the next step of the episode) is an error: the
wrapped policy is stateful. One adapter plays one episode at a time: serve it to one client
(``serve --protocol openpi`` gives each connection an adapter of its own).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import EpisodeContext, Policy, seed_globals
from awda_bench.serving.openpi_schema import (
    ACTIONS,
    DEFAULT_DEMO_FRAMES,
    DONE,
    EPISODE_ID,
    OBSERVATION_KEYS,
    STEP,
    WAYPOINTS,
    RequestObservations,
    request_spec,
    server_metadata,
)
from awda_bench.serving.protocol import ServerInfo


def declared_keys(policy: Policy) -> tuple[str, ...]:
    """The observation keys ``policy`` reads: its ``observation_keys`` attribute where it has
    one (checked against the schema), else all of them."""
    keys = getattr(policy, "observation_keys", None)
    if keys is None:
        return OBSERVATION_KEYS
    unknown = sorted(set(keys) - set(OBSERVATION_KEYS))
    if unknown:
        raise ValueError(
            f"{type(policy).__name__}.observation_keys names {unknown}, not observation keys; "
            f"choose among {', '.join(OBSERVATION_KEYS)}"
        )
    return tuple(k for k in OBSERVATION_KEYS if k in keys)


class OpenpiAdapter:
    """``policy`` answering openpi requests (duck-types ``openpi_client.base_policy.BasePolicy``)."""

    def __init__(
        self,
        policy: Policy,
        *,
        info: ServerInfo | None = None,
        method: str = "",
        demo_frames: int = DEFAULT_DEMO_FRAMES,
    ) -> None:
        self.policy = policy
        name = method or getattr(policy, "name", "") or type(policy).__name__
        self.info = info or ServerInfo(name, "builtin", "builtin", 0, learned=False)
        self.metadata: dict[str, Any] = server_metadata(
            self.info, declared_keys(policy), demo_frames
        )
        """What a server should send on connect (``WebsocketPolicyServer(..., metadata=)``)."""
        self._episode: str | None = None
        self._step = 0
        self._observations: RequestObservations | None = None

    def reset(self) -> None:
        """Forget the episode in progress (openpi's ``BasePolicy.reset``)."""
        self._episode, self._observations, self._step = None, None, 0

    def infer(self, obs: dict[str, Any]) -> dict[str, Any]:
        spec = request_spec(obs)
        episode, step = str(obs[EPISODE_ID]), int(obs[STEP])
        if step == 0 or episode != self._episode or self._observations is None:
            if step != 0:
                raise ValueError(
                    f"episode {episode!r} starts at step {step}; its first request must be step 0"
                )
            self._episode, self._step = episode, 0
            self._observations = RequestObservations(obs)
            seed_globals(spec.seed)
            self.policy.reset(
                EpisodeContext(None, spec, observations=self._observations, method=self.info.method)
            )
        elif step != self._step:
            raise ValueError(
                f"episode {episode!r}: request for step {step}, expected step {self._step} (this "
                "policy answers one action per request; play each before asking again)"
            )
        else:
            self._observations.update(obs)
        if self.policy.done:
            reply: dict[str, Any] = {ACTIONS: np.zeros((0, 4), np.float32), DONE: True}
        else:
            action = np.asarray(self.policy.act(self._observations))
            self._step += 1
            if action.shape == (1, 4):  # env 0's action; another shape goes as it is, refused
                action = action[0]
            reply = {ACTIONS: action, DONE: bool(self.policy.done)}
        waypoints = self.policy.waypoints
        if waypoints is not None:
            reply[WAYPOINTS] = np.asarray(waypoints, dtype=float)
        return reply
