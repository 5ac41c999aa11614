"""What crosses openpi's websocket policy protocol in this benchmark: the observation dict the
harness sends, the reply it reads, and the server metadata it understands.

The conversation is openpi's (``openpi_client.websocket_client_policy`` /
``openpi_server.WebsocketPolicyServer``)::

    client (the harness: OpenpiPolicy)            server (any openpi policy server)
      connect ------------------------------->
              <------------------------------   metadata  (a msgpack map; may be empty)
      observation dict ----------------------->   policy.infer(obs)
              <------------------------------   {"actions": (4,) or (H, 4), "server_timing": ...}
      ... one request whenever the played chunk is used up
              <------------------------------   a text frame instead: the server's traceback
                                                (openpi's server then closes the connection)

Arrays are msgpack maps ``{b"__ndarray__": True, b"data", b"dtype", b"shape"}``
(:func:`~.wire.pack_openpi`).

The observation dict (one robot: env 0 of the episode; world frame, z up, metres)::

    episode_id                  str   "SUITE/TASK/EPISODE/SEED", the same on every request of one
                                      episode: a stateful server tells episodes apart by it
    step                        int   the control step this request is for (0 at the first)
    episode/suite, episode/task, episode/episode, episode/seed, episode/demo_seed
                                      the episode's spec (a server seeds its generators from seed)
    demo/frames                 (N, 240, 320, 3) uint8  the demonstration (N = metadata
                                      demo_frames, default 10); on step 0 only
    observation/image           (240, 320, 3) uint8     the third-person RGB frame now
    observation/wrist_depth     (128, 128) float32      wrist camera depth [m], 0 = no hit
    observation/wrist_intrinsics (3, 3) float64         its OpenCV intrinsics [px]
    observation/wrist_cam2world (4, 4) float64          its camera-to-world pose, OpenCV axes
    observation/state           (17,) float64           tcp_pos (3), tcp_quat w,x,y,z (4),
                                                        gripper_opening_m (1), qpos (9)
    observation/camera_intrinsics (3, 3) float64        third-person camera, OpenCV
    observation/camera_extrinsics (3, 4) float64        its world-to-camera transform

The reply: ``actions`` (4,) (dx, dy, dz, grip in [-1, 1], one step) or (H, 4) (a chunk, played
step by step; the next request goes out when it is used up, or after ``action_horizon`` of its
actions); optionally ``done`` (true: the episode ends once this reply's actions are played) and
``waypoints`` ((K, 3 + k) floats, recorded with the episode); ``server_timing`` (openpi's server
adds it) is summarised into the episode's row. Everything else is ignored.

The metadata (all optional; openpi's server sends whatever it was given)::

    observation_keys  list of the keys above to send (default: all; the episode keys always go).
                      Each costs a render (~50 ms on a CPU renderer): list only what is read
    demo_frames       N of demo/frames (default 10)
    action_horizon    play at most this many actions of each chunk, then ask again (default:
                      the whole chunk, like openpi's ActionChunkBroker with the chunk's length)
    method, snapshot, snapshot_name, snapshot_order, learned
                      what is served: name and key the rows. Without ``method`` the rows are
                      named ``openpi`` (``run --label`` renames them); without ``snapshot`` they
                      are keyed by a hash of the metadata
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.episode import EpisodeSpec, Observations, Proprioception, WristDepth
from awda_bench.errors import RemotePolicyError
from awda_bench.serving.protocol import OPENPI, ServerInfo

EPISODE_ID = "episode_id"
STEP = "step"
SPEC_KEYS = {
    "episode/suite": "suite",
    "episode/task": "task",
    "episode/episode": "episode",
    "episode/seed": "seed",
    "episode/demo_seed": "demo_seed",
}
"""Request key -> :class:`~awda_bench.episode.EpisodeSpec` field, on every request."""

DEMO_FRAMES = "demo/frames"
IMAGE = "observation/image"
WRIST_DEPTH = "observation/wrist_depth"
WRIST_INTRINSICS = "observation/wrist_intrinsics"
WRIST_CAM2WORLD = "observation/wrist_cam2world"
STATE = "observation/state"
CAMERA_INTRINSICS = "observation/camera_intrinsics"
CAMERA_EXTRINSICS = "observation/camera_extrinsics"
OBSERVATION_KEYS = (
    DEMO_FRAMES,
    IMAGE,
    WRIST_DEPTH,
    WRIST_INTRINSICS,
    WRIST_CAM2WORLD,
    STATE,
    CAMERA_INTRINSICS,
    CAMERA_EXTRINSICS,
)
"""The observation keys a server may ask for (``observation_keys``), in the order they render."""

STATE_LAYOUT = (("tcp_pos", 3), ("tcp_quat", 4), ("gripper_opening_m", 1), ("qpos", 9))
"""``observation/state``: the :class:`~awda_bench.episode.Proprioception` fields, concatenated."""

ACTIONS = "actions"
DONE = "done"
WAYPOINTS = "waypoints"
SERVER_TIMING = "server_timing"

DEFAULT_DEMO_FRAMES = 10
"""``demo/frames`` count when the metadata does not say (the :class:`Observations` default)."""
DEFAULT_METHOD_NAME = "openpi"
"""The rows' name when the metadata has no ``method``."""


def jsonable(value: Any) -> Any:
    """A msgpack value (arrays decoded) as JSON can store it: arrays as lists, bytes as their
    length, keys as text."""
    if isinstance(value, dict):
        return {
            (k.decode(errors="replace") if isinstance(k, bytes) else str(k)): jsonable(v)
            for k, v in value.items()
        }
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes):
        return f"<{len(value)} bytes>"
    return value


@dataclass(frozen=True)
class OpenpiOptions:
    """What the harness takes from a server's metadata about the conversation."""

    observation_keys: tuple[str, ...] = OBSERVATION_KEYS
    """Observation keys to send, in :data:`OBSERVATION_KEYS` order."""
    demo_frames: int = DEFAULT_DEMO_FRAMES
    """Frames of ``demo/frames``."""
    action_horizon: int | None = None
    """Actions of a chunk played before asking again (``None``: all of them)."""

    @classmethod
    def from_metadata(cls, metadata: dict[str, Any], peer: str) -> OpenpiOptions:
        """The options ``metadata`` asks for; a one-line error naming a bad value."""
        keys = metadata.get("observation_keys", OBSERVATION_KEYS)
        if not isinstance(keys, list | tuple) or not all(isinstance(k, str) for k in keys):
            raise RemotePolicyError(
                f"{peer}'s metadata observation_keys is {keys!r}, not a list of key names"
            )
        unknown = sorted(set(keys) - set(OBSERVATION_KEYS))
        if unknown:
            raise RemotePolicyError(
                f"{peer}'s metadata asks for observation keys {unknown} that this harness does "
                f"not send; choose among {', '.join(OBSERVATION_KEYS)}"
            )
        return cls(
            observation_keys=tuple(k for k in OBSERVATION_KEYS if k in keys),
            demo_frames=_positive(metadata, "demo_frames", DEFAULT_DEMO_FRAMES, peer),
            action_horizon=_positive(metadata, "action_horizon", None, peer),
        )


def _positive(metadata: dict[str, Any], key: str, default: Any, peer: str) -> Any:
    value = metadata.get(key, default)
    if value is default:
        return value
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise RemotePolicyError(f"{peer}'s metadata {key} is {value!r}, not a positive integer")
    return int(value)


def server_info(metadata: Any, peer: str) -> ServerInfo:
    """What an openpi server serves, as its metadata says (the rows are named and keyed by it)."""
    if not isinstance(metadata, dict):
        raise RemotePolicyError(
            f"{peer} sent {type(metadata).__name__} as its metadata, not a map; is it an openpi "
            "policy server?"
        )
    method = metadata.get("method")
    if not isinstance(method, str) or not method.strip():
        method = DEFAULT_METHOD_NAME
    snapshot = metadata.get("snapshot")
    if snapshot is None:
        blob = json.dumps(jsonable(metadata), sort_keys=True, separators=(",", ":"))
        snapshot = hashlib.sha256(blob.encode()).hexdigest()[:16]
    name = metadata.get("snapshot_name", "metadata")
    order = metadata.get("snapshot_order", 0)
    return ServerInfo(
        method=method,
        snapshot=str(snapshot),
        snapshot_name=str(name),
        snapshot_order=int(order) if isinstance(order, int | np.integer) else 0,
        learned=bool(metadata.get("learned", False)),
        protocol=OPENPI,
    )


def server_metadata(
    info: ServerInfo, observation_keys: tuple[str, ...], demo_frames: int
) -> dict[str, Any]:
    """The metadata ``serve --protocol openpi`` sends: what it serves and what it reads."""
    return {
        "method": info.method,
        "snapshot": info.snapshot,
        "snapshot_name": info.snapshot_name,
        "snapshot_order": info.snapshot_order,
        "learned": info.learned,
        "observation_keys": list(observation_keys),
        "demo_frames": demo_frames,
        "action_dim": 4,
        "server": "awda_bench serve --protocol openpi",
    }


def episode_id(spec: EpisodeSpec) -> str:
    return f"{spec.suite}/{spec.task}/{spec.episode}/{spec.seed}"


def observation_request(
    observations: Observations, spec: EpisodeSpec, step: int, options: OpenpiOptions
) -> dict[str, Any]:
    """The request for ``step`` of ``spec``'s episode: the episode keys and the observation keys
    ``options`` asks for, rendered now (env 0)."""
    request: dict[str, Any] = {EPISODE_ID: episode_id(spec), STEP: step}
    for key, name in SPEC_KEYS.items():
        request[key] = getattr(spec, name)
    keys = options.observation_keys
    if DEMO_FRAMES in keys and step == 0:
        request[DEMO_FRAMES] = np.asarray(observations.demo_frames(options.demo_frames))
    if IMAGE in keys:
        request[IMAGE] = np.asarray(observations.rgb())[0]
    if {WRIST_DEPTH, WRIST_INTRINSICS, WRIST_CAM2WORLD} & set(keys):
        wrist = observations.wrist_depth()
        for key, value in (
            (WRIST_DEPTH, wrist.depth_m),
            (WRIST_INTRINSICS, wrist.intrinsic_cv),
            (WRIST_CAM2WORLD, wrist.cam2world_cv),
        ):
            if key in keys:
                request[key] = np.asarray(value)[0]
    if STATE in keys:
        proprio = observations.proprio()
        request[STATE] = np.concatenate(
            [np.asarray(getattr(proprio, name)).reshape(1, -1)[0] for name, _ in STATE_LAYOUT]
        )
    if {CAMERA_INTRINSICS, CAMERA_EXTRINSICS} & set(keys):
        intrinsic, extrinsic = observations.camera()
        if CAMERA_INTRINSICS in keys:
            request[CAMERA_INTRINSICS] = np.asarray(intrinsic)
        if CAMERA_EXTRINSICS in keys:
            request[CAMERA_EXTRINSICS] = np.asarray(extrinsic)
    return request


def request_spec(request: dict[str, Any]) -> EpisodeSpec:
    """The episode spec a request carries (a one-line error naming a missing key)."""
    missing = [k for k in (EPISODE_ID, STEP, *SPEC_KEYS) if k not in request]
    if missing:
        raise KeyError(
            f"the request has no {', '.join(missing)}: an awda_bench policy needs the episode "
            "keys of docs/serving.md's observation schema on every request"
        )
    return EpisodeSpec(**{name: request[key] for key, name in SPEC_KEYS.items()})


class RequestObservations:
    """The :class:`~awda_bench.episode.Observations` of an episode whose observations arrive as
    request dicts (the server's side): each call reads the current request."""

    num_envs = 1

    def __init__(self, first: dict[str, Any]) -> None:
        self._request = first
        self._first = first

    def update(self, request: dict[str, Any]) -> None:
        """The next request of the same episode."""
        self._request = request

    def _get(self, key: str, call: str, request: dict[str, Any] | None = None) -> np.ndarray:
        request = self._request if request is None else request
        if key not in request:
            raise KeyError(
                f"{call} reads {key!r}, which the client did not send; list it in the server's "
                "metadata observation_keys"
            )
        return np.asarray(request[key])

    def demo_frames(self, count: int = DEFAULT_DEMO_FRAMES) -> np.ndarray:
        frames = self._get(DEMO_FRAMES, "demo_frames()", self._first)
        if len(frames) != count:
            raise ValueError(
                f"demo_frames({count}) asked for, the client sent {len(frames)} frames; set the "
                f"server's metadata demo_frames to {count}"
            )
        return frames

    def first_frame(self) -> np.ndarray:
        return self._get(IMAGE, "first_frame()", self._first)

    def rgb(self) -> np.ndarray:
        return self._get(IMAGE, "rgb()")[None]

    def wrist_depth(self) -> WristDepth:
        return WristDepth(
            self._get(WRIST_DEPTH, "wrist_depth()")[None],
            self._get(WRIST_INTRINSICS, "wrist_depth()")[None],
            self._get(WRIST_CAM2WORLD, "wrist_depth()")[None],
        )

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        return (
            self._get(CAMERA_INTRINSICS, "camera()"),
            self._get(CAMERA_EXTRINSICS, "camera()"),
        )

    def proprio(self) -> Proprioception:
        state = self._get(STATE, "proprio()")
        parts, start = {}, 0
        for name, size in STATE_LAYOUT[:-1]:
            parts[name] = state[start : start + size]
            start += size
        parts[STATE_LAYOUT[-1][0]] = state[start:]
        return Proprioception(
            tcp_pos=parts["tcp_pos"][None],
            tcp_quat=parts["tcp_quat"][None],
            gripper_opening_m=parts["gripper_opening_m"],
            qpos=parts["qpos"][None],
        )
