"""Torch datasets over a collected DATA_DIR, in the batch formats :mod:`awda_bench.models` documents.

:class:`AwdaPairDataset` (``AwdaNet.compute_loss``), one sample per pair::

    task-driven (head 0): every demonstrator episode d of task t  x  every agent episode a of t
        "demo"        (demo_frames, 3, H, W)  d's frames at round(linspace(0, T_d, demo_frames)):
                                              first and last included
        "first_frame" (3, H, W)               a's frame 0
        "trajectory"  (P, 3 + k)              a's TCP xyz (world frame [m]) at P points evenly
                                              spaced in time over states 0..T_a (linear), plus
                                              the k mined attributes (nearest step, 0/1);
                                              trajectory[0] is the TCP at the first frame
        "demo_trajectory" (P, 3 + k)          the same of d (its grasp labels the identification
                                              loss, :mod:`awda_bench.models.identification_loss`)
        "contact", "demo_contact" (4,)        only with ``contact_points=True``: the TCP xyz
                                              where a (d) first moves the task's object, and 1;
                                              zeros where none (the identification label of
                                              episodes without a grasp,
                                              :mod:`awda_bench.data.contact_point`)
        "head"        ()  int64               0
        "camera"      ()  int64               the index of a's third-person camera among
                                              ``cameras`` (the distinct cameras of the pairs'
                                              agents, in order of first appearance, unless the
                                              caller lists them): MOSAIC films door and drawer
                                              from one side, its other families from another
    synthesized (head 1): each synthesized episode paired with itself (demo = its own frames)

Pairs never cross tasks (agent and demonstrator scenes of one task differ: their seeds are hashed
with different roles) and never come from a ``test`` collection unless ``allow_test=True`` (a
validation set). MOSAIC's leave-one-family-out training set is
``selection=Selection(exclude_families=("door",))``.

:class:`TosviDataset` (``TosviNet.compute_loss``), one sample per agent step ``t``::

    "demo"    (demo_frames, 3, H, W)   a demonstrator episode of the same task (fixed per sample:
                                       index (7919 * a + t) mod D among the task's D demos)
    "frames"  (frame_stack, 3, H, W)   agent frames t-5 .. t (indices below 0 repeat frame 0)
    "actions" (frame_stack, 4)         the actions taken at those frames (a_t is the target)
    "depth"   (frame_stack, 1, Hd, Wd) wrist depth [m] at those frames (``with_depth=True``)

Images are RGB float32 in [0, 1], channels first; resized with OpenCV (area) when ``image_size``
differs from the collected size. Files are opened lazily, once per process (DataLoader workers
each open their own handles).
"""

from __future__ import annotations

import copy
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import torch

from awda_bench.data.collect import MANIFEST
from awda_bench.data.config import ROLE_AGENT, ROLE_DEMONSTRATOR, ROLE_SYNTHESIZED
from awda_bench.data.contact_point import first_object_motion
from awda_bench.data.trajectory_file import decode_jpeg, load_unit_json
from awda_bench.episode import demo_frame_indices
from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.models.agent_cameras import CameraMatrices, camera_index


@dataclass(frozen=True)
class EpisodeRef:
    """Where one kept episode lives and what it is."""

    role: str
    task: int
    family: str
    file: Path
    """The unit's ``.h5`` file."""
    traj: str
    """Group name inside it (``traj_<i>``)."""
    steps: int
    """T: actions in the episode (T + 1 frames)."""
    meta: dict[str, Any]
    """The episode's JSON entry."""


@dataclass(frozen=True)
class Selection:
    """Which tasks/families a dataset draws from (MOSAIC leave-one-family-out:
    ``Selection(exclude_families=("door",))``)."""

    tasks: tuple[int, ...] | None = None
    """Only these task indices (``None``: all)."""
    families: tuple[str, ...] | None = None
    """Only these families (``None``: all)."""
    exclude_families: tuple[str, ...] = ()
    """Never these families."""

    def keeps(self, ref: EpisodeRef) -> bool:
        return (
            (self.tasks is None or ref.task in self.tasks)
            and (self.families is None or ref.family in self.families)
            and ref.family not in self.exclude_families
        )


class CollectedData:
    """Read-only view of a DATA_DIR written by ``collect``."""

    def __init__(self, root: Path | str, *, allow_incomplete: bool = False) -> None:
        import json

        self.root = Path(root)
        path = self.root / MANIFEST
        if not path.is_file():
            raise UsageError(
                f"{self.root} holds no {MANIFEST}: not a collect directory; "
                "create one with python -m awda_bench collect"
            )
        try:
            self.manifest: dict[str, Any] = json.loads(path.read_text())
            units = self.manifest["units"]
        except (OSError, ValueError, KeyError) as exc:
            raise CorruptFileError(
                f"{path} is unreadable ({exc}); re-run the collect command that made it"
            ) from exc
        if not self.manifest.get("complete") and not allow_incomplete:
            raise UsageError(
                f"the collection in {self.root} is incomplete; re-run its collect command to "
                "finish it (or pass allow_incomplete=True)"
            )
        self.episodes: list[EpisodeRef] = []
        for unit in units:
            if not unit.get("complete"):
                continue
            h5_path = self.root / unit["file"]
            payload = load_unit_json(h5_path.with_suffix(".json"))
            for episode in payload["episodes"]:
                self.episodes.append(
                    EpisodeRef(
                        role=unit["role"],
                        task=int(unit["task"]),
                        family=unit["family"],
                        file=h5_path,
                        traj=f"traj_{episode['episode_id']}",
                        steps=int(episode["elapsed_steps"]),
                        meta=episode,
                    )
                )
        self._files: dict[Path, h5py.File] = {}
        self._pid = os.getpid()

    @property
    def fingerprint(self) -> str:
        """The collection's fingerprint (what a training snapshot records about its data)."""
        return str(self.manifest.get("fingerprint", ""))

    @property
    def split(self) -> str:
        return str(self.manifest.get("definition", {}).get("split", ""))

    def select(self, role: str, selection: Selection | None = None) -> list[EpisodeRef]:
        """The episodes of ``role`` that ``selection`` (default: all) keeps, in file order."""
        selection = selection or Selection()
        return [e for e in self.episodes if e.role == role and selection.keeps(e)]

    def group(self, ref: EpisodeRef) -> h5py.Group:
        if os.getpid() != self._pid:  # a forked DataLoader worker: never share HDF5 handles
            self._files, self._pid = {}, os.getpid()
        handle = self._files.get(ref.file)
        if handle is None:
            try:
                handle = h5py.File(ref.file, "r")
            except OSError as exc:
                raise CorruptFileError(
                    f"{ref.file} is unreadable ({exc}); delete it (and its .json) and re-run the "
                    "collect command to record that unit again"
                ) from exc
            self._files[ref.file] = handle
        try:
            return handle[ref.traj]
        except KeyError as exc:
            raise CorruptFileError(
                f"{ref.file} lacks {ref.traj}; delete it and re-run the collect command"
            ) from exc

    def _read(self, ref: EpisodeRef, key: str, index: Any = ()) -> np.ndarray:
        try:
            return np.asarray(self.group(ref)[key][index])
        except (KeyError, OSError, ValueError) as exc:
            raise CorruptFileError(
                f"{ref.file}:{ref.traj}/{key} is unreadable ({exc}); delete the file and re-run "
                "the collect command"
            ) from exc

    def frames(self, ref: EpisodeRef, indices: Iterable[int]) -> np.ndarray:
        """(k, H, W, 3) uint8 RGB third-person frames at state indices."""
        dataset = "obs/sensor_data/third_person/rgb_jpeg"
        out = []
        for i in indices:
            try:
                out.append(decode_jpeg(self._read(ref, dataset, int(i))))
            except ValueError as exc:
                raise CorruptFileError(
                    f"{ref.file}:{ref.traj} frame {i} is not a JPEG ({exc}); delete the file and "
                    "re-run the collect command"
                ) from exc
        return np.stack(out)

    def tcp_pos(self, ref: EpisodeRef) -> np.ndarray:
        """(T + 1, 3) TCP positions, world frame [m]."""
        return self._read(ref, "obs/extra/tcp_pose")[:, :3].astype(np.float64)

    def contact_point(self, ref: EpisodeRef) -> np.ndarray:
        """``(4,)`` float32: the TCP [m] where the episode first moves the scene's object and 1,
        or zeros where it has no such moment (:mod:`awda_bench.data.contact_point`). Read from
        the recorded joint state: Meta-World's ``env_states/qpos``, whose leading joints are the
        robot's ``obs/agent/qpos``; ManiSkill's episodes record their state per actor, not as
        one joint vector, and have no contact point (zeros)."""
        group = self.group(ref)
        if "env_states/qpos" not in group or "obs/agent/qpos" not in group:
            return np.zeros(4, np.float32)
        robot_joints = group["obs/agent/qpos"].shape[1]
        step = first_object_motion(self._read(ref, "env_states/qpos")[:, robot_joints:])
        if step is None:
            return np.zeros(4, np.float32)
        return np.append(self.tcp_pos(ref)[step], 1.0).astype(np.float32)

    def attributes(self, ref: EpisodeRef, names: Iterable[str]) -> np.ndarray:
        """(T, k) mined attributes as floats."""
        cols = [self._read(ref, f"attributes/{n}").astype(np.float32) for n in names]
        return np.stack(cols, axis=1) if cols else np.zeros((ref.steps, 0), np.float32)

    def actions(self, ref: EpisodeRef) -> np.ndarray:
        return self._read(ref, "actions").astype(np.float32)

    def camera(self, ref: EpisodeRef) -> tuple[np.ndarray, np.ndarray]:
        """The third-person camera at the episode's first state: ``intrinsic_cv`` (3, 3) and the
        world-to-camera ``extrinsic_cv`` (3, 4), OpenCV conventions."""
        base = "obs/sensor_param/third_person"
        intrinsic = self._read(ref, f"{base}/intrinsic_cv", 0).astype(np.float64)
        return intrinsic, self._read(ref, f"{base}/extrinsic_cv", 0).astype(np.float64)

    def depth_m(self, ref: EpisodeRef, indices: Iterable[int]) -> np.ndarray:
        """(k, Hd, Wd, 1) float32 wrist depth [m] (agent roles only)."""
        idx = np.asarray(list(indices), dtype=np.int64)
        unique, inverse = np.unique(idx, return_inverse=True)
        mm = self._read(ref, "obs/sensor_data/wrist_depth/depth", unique)
        return (mm[inverse].astype(np.float32) / 1000.0).reshape(len(idx), *mm.shape[1:])

    def close(self) -> None:
        for handle in self._files.values():
            handle.close()
        self._files.clear()


def frames_tensor(frames: np.ndarray, size: tuple[int, int] | None) -> torch.Tensor:
    """(k, H, W, 3) uint8 -> (k, 3, H', W') float32 in [0, 1]."""
    if size is not None and tuple(frames.shape[1:3]) != tuple(size):
        import cv2

        frames = np.stack(
            [cv2.resize(f, (size[1], size[0]), interpolation=cv2.INTER_AREA) for f in frames]
        )
    return torch.from_numpy(np.ascontiguousarray(frames)).permute(0, 3, 1, 2).float() / 255.0


def resample_trajectory(tcp: np.ndarray, attributes: np.ndarray, points: int) -> np.ndarray:
    """(T+1, 3) positions and (T, k) attributes -> (points, 3 + k) (see the module docstring)."""
    n = len(tcp)
    s = np.linspace(0.0, n - 1, points)
    xyz = np.stack([np.interp(s, np.arange(n), tcp[:, j]) for j in range(3)], axis=1)
    if attributes.shape[1]:
        full = np.concatenate([attributes, attributes[-1:]], axis=0)  # state T takes the last
        flags = full[np.clip(np.round(s).astype(np.int64), 0, n - 1)]
    else:
        flags = np.zeros((points, 0))
    return np.concatenate([xyz, flags], axis=1).astype(np.float32)


def _check_split(data: CollectedData, allow_test: bool) -> None:
    if data.split == "test" and not allow_test:
        raise UsageError(
            f"{data.root} is a test-split collection (held-out tasks): training never draws "
            "from it; pass allow_test=True only for a validation set"
        )


class AwdaPairDataset:
    """AWDA samples (module docstring); ``len`` = sum over tasks of agents x demos + synthesized."""

    def __init__(
        self,
        data: CollectedData,
        *,
        demo_frames: int = 10,
        trajectory_points: int = 50,
        attributes: tuple[str, ...] = ("grasp",),
        image_size: tuple[int, int] | None = None,
        selection: Selection | None = None,
        include_synthesized: bool = True,
        allow_test: bool = False,
        cameras: Sequence[CameraMatrices] | None = None,
        contact_points: bool = False,
    ) -> None:
        _check_split(data, allow_test)
        if demo_frames < 2 or trajectory_points < 2:
            raise UsageError("demo_frames and trajectory_points must be >= 2")
        self.data = data
        self.demo_frames = demo_frames
        self.trajectory_points = trajectory_points
        self.attributes = attributes
        self.image_size = image_size
        self.contact_points = contact_points
        agents = data.select(ROLE_AGENT, selection)
        demos = data.select(ROLE_DEMONSTRATOR, selection)
        self.pairs: list[tuple[EpisodeRef, EpisodeRef, int]] = []
        by_task: dict[int, list[EpisodeRef]] = {}
        for d in demos:
            by_task.setdefault(d.task, []).append(d)
        for a in agents:
            for d in by_task.get(a.task, []):
                self.pairs.append((a, d, 0))
        if include_synthesized:
            for s in data.select(ROLE_SYNTHESIZED, selection):
                self.pairs.append((s, s, 1))
        if not self.pairs:
            raise UsageError(
                f"no AWDA pairs in {data.root} for this selection (needs agent and demonstrator "
                "episodes of the same task, or synthesized ones)"
            )
        filmed: dict[tuple[str, str], CameraMatrices] = {}
        for agent, _, _ in self.pairs:
            filmed.setdefault((str(agent.file), agent.traj), data.camera(agent))
        self._filmed = [filmed[(str(a.file), a.traj)] for a, _, _ in self.pairs]
        """Each pair's agent camera (demonstrator and agent share the scene's)."""
        own: list[CameraMatrices] = []
        for camera in filmed.values():
            if camera_index(own, camera) is None:
                own.append(camera)
        self.cameras: list[CameraMatrices] = []
        """The cameras ``"camera"`` indexes (:meth:`index_cameras`)."""
        self.pair_camera: list[int] = []
        """Each pair's ``"camera"``."""
        self.index_cameras(own if cameras is None else cameras)

    def index_cameras(self, cameras: Sequence[CameraMatrices]) -> None:
        """Index every pair's camera among ``cameras`` (a list that holds this dataset's and
        perhaps more: a training set's and its validation set's together)."""
        indices = [camera_index(cameras, c) for c in self._filmed]
        if any(i is None for i in indices):
            raise UsageError(
                f"an episode of {self.data.root} was filmed by a camera not among the {len(cameras)} "
                "listed; list every camera the pairs were filmed with"
            )
        self.cameras = list(cameras)
        self.pair_camera = [int(i) for i in indices if i is not None]

    def __len__(self) -> int:
        return len(self.pairs)

    def trajectory(self, agent: EpisodeRef) -> np.ndarray:
        """The ``"trajectory"`` label of an episode ``(P, 3 + k)`` (``"demo_trajectory"`` of a
        demonstrator's)."""
        return resample_trajectory(
            self.data.tcp_pos(agent),
            self.data.attributes(agent, self.attributes),
            self.trajectory_points,
        )

    def contact(self, ref: EpisodeRef) -> np.ndarray:
        """The ``"contact"`` label of an episode ``(4,)`` (``"demo_contact"`` of a
        demonstrator's): :meth:`CollectedData.contact_point` for task-driven episodes, zeros
        (no label) for synthesized ones, whose touches demonstrate nothing."""
        if ref.role == ROLE_SYNTHESIZED:
            return np.zeros(4, np.float32)
        return self.data.contact_point(ref)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        agent, demo, head = self.pairs[index]
        demo_idx = demo_frame_indices(demo.steps, self.demo_frames)
        trajectory = self.trajectory(agent)
        sample = {
            "demo": frames_tensor(self.data.frames(demo, demo_idx), self.image_size),
            "first_frame": frames_tensor(self.data.frames(agent, [0]), self.image_size)[0],
            "trajectory": torch.from_numpy(trajectory),
            "demo_trajectory": torch.from_numpy(self.trajectory(demo)),
            "head": torch.tensor(head, dtype=torch.int64),
            "camera": torch.tensor(self.pair_camera[index], dtype=torch.int64),
        }
        if self.contact_points:
            sample["contact"] = torch.from_numpy(self.contact(agent))
            sample["demo_contact"] = torch.from_numpy(self.contact(demo))
        return sample


class TosviDataset:
    """T-OSVI samples (module docstring); ``len`` = total agent steps of the selection."""

    def __init__(
        self,
        data: CollectedData,
        *,
        demo_frames: int = 10,
        frame_stack: int = 6,
        with_depth: bool = False,
        image_size: tuple[int, int] | None = None,
        depth_size: tuple[int, int] | None = None,
        selection: Selection | None = None,
        include_synthesized: bool = False,
        allow_test: bool = False,
    ) -> None:
        _check_split(data, allow_test)
        if frame_stack < 1:
            raise UsageError(f"frame_stack must be >= 1, got {frame_stack}")
        self.data = data
        self.demo_frames = demo_frames
        self.frame_stack = frame_stack
        self.with_depth = with_depth
        self.image_size = image_size
        self.depth_size = depth_size
        demos: dict[int, list[EpisodeRef]] = {}
        for d in data.select(ROLE_DEMONSTRATOR, selection):
            demos.setdefault(d.task, []).append(d)
        self.samples: list[tuple[EpisodeRef, EpisodeRef, int]] = []
        for a_index, agent in enumerate(data.select(ROLE_AGENT, selection)):
            task_demos = demos.get(agent.task, [])
            if not task_demos:
                continue
            for t in range(agent.steps):
                demo = task_demos[(7919 * a_index + t) % len(task_demos)]
                self.samples.append((agent, demo, t))
        if include_synthesized:
            for s in data.select(ROLE_SYNTHESIZED, selection):
                self.samples += [(s, s, t) for t in range(s.steps)]
        if not self.samples:
            raise UsageError(
                f"no T-OSVI samples in {data.root} for this selection (needs agent and "
                "demonstrator episodes of the same task)"
            )

    def __len__(self) -> int:
        return len(self.samples)

    def subset(self, indices: Iterable[int]) -> TosviDataset:
        """This dataset reduced to the samples at ``indices``, in that order."""
        reduced = copy.copy(self)
        reduced.samples = [self.samples[i] for i in indices]
        if not reduced.samples:
            raise UsageError("a T-OSVI subset needs at least one sample")
        return reduced

    def stack_indices(self, t: int) -> np.ndarray:
        """The state indices of step ``t``'s agent stack: ``t-5 .. t``, those below 0 at 0."""
        return np.clip(np.arange(t - self.frame_stack + 1, t + 1), 0, None)

    def depth_stack(self, agent: EpisodeRef, stack: np.ndarray) -> torch.Tensor:
        """Wrist depth ``(len(stack), 1, Hd, Wd)`` [m] at ``stack``, nearest-resized to
        ``depth_size``."""
        depth = self.data.depth_m(agent, stack)[..., 0]  # (S, Hd, Wd)
        if self.depth_size is not None and tuple(depth.shape[1:]) != tuple(self.depth_size):
            import cv2

            h, w = self.depth_size
            depth = np.stack(
                [cv2.resize(d, (w, h), interpolation=cv2.INTER_NEAREST) for d in depth]
            )
        return torch.from_numpy(np.ascontiguousarray(depth))[:, None]

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        agent, demo, t = self.samples[index]
        stack = self.stack_indices(t)
        sample = {
            "demo": frames_tensor(
                self.data.frames(demo, demo_frame_indices(demo.steps, self.demo_frames)),
                self.image_size,
            ),
            "frames": frames_tensor(self.data.frames(agent, stack), self.image_size),
            "actions": torch.from_numpy(self.data.actions(agent)[stack]),
        }
        if self.with_depth:
            sample["depth"] = self.depth_stack(agent, stack)
        return sample
