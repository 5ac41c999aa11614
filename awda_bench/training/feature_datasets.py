"""Training datasets served from a frozen backbone's feature cache instead of images.

Each wrapper yields the same samples, in the same order, as the dataset it wraps, with the images
replaced by their cached feature maps (:mod:`awda_bench.training.feature_cache`), and names the
frames it reads (``frames_needed``, ``tosvi_frames_needed``) so the cache encodes exactly those.

:class:`CachedAwdaPairs` (:class:`~awda_bench.data.datasets.AwdaPairDataset`)::

    "demo_features"        (demo_frames, C, h, w) float32
    "first_frame_features" (C, h, w) float32
    "trajectory", "demo_trajectory", "head", "camera"   as AwdaPairDataset
    "contact", "demo_contact"                           as AwdaPairDataset (contact_points=True)

:class:`CachedTosviSamples` (:class:`~awda_bench.data.datasets.TosviDataset`)::

    "demo_features"  (demo_frames, C, h, w) float32
    "frame_features" (frame_stack, C, h, w) float32   agent frames t-5 .. t (below 0: frame 0)
    "actions"        (frame_stack, 4)                  as TosviDataset
    "depth"          (frame_stack, 1, Hd, Wd) [m]      as TosviDataset (+depth: its depth ResNet
                                                       is trained, so depth stays images, read
                                                       from the episode files per sample)

Labels (trajectories, actions) are read once and kept in memory.
"""

from __future__ import annotations

import numpy as np
import torch

from awda_bench.data.datasets import AwdaPairDataset, EpisodeRef, TosviDataset
from awda_bench.episode import demo_frame_indices
from awda_bench.training.feature_cache import FeatureCache, episode_name


def _key(ref: EpisodeRef) -> tuple[str, str]:
    return str(ref.file), ref.traj


def frames_needed(pairs: AwdaPairDataset) -> list[tuple[EpisodeRef, np.ndarray]]:
    """Every episode the pairs read, with the sorted state indices they read of it (o_1 = state 0
    for agents; the demo frames for demonstrators; both for self-paired synthesized episodes)."""
    refs: dict[tuple[str, str], EpisodeRef] = {}
    needed: dict[tuple[str, str], set[int]] = {}
    for agent, demo, _ in pairs.pairs:
        for ref, idx in ((agent, [0]), (demo, demo_frame_indices(demo.steps, pairs.demo_frames))):
            key = (str(ref.file), ref.traj)
            refs[key] = ref
            needed.setdefault(key, set()).update(int(i) for i in idx)
    return [(refs[k], np.array(sorted(v), dtype=np.int64)) for k, v in needed.items()]


class CachedAwdaPairs:
    """``pairs`` with feature maps from ``cache`` (module docstring)."""

    def __init__(self, pairs: AwdaPairDataset, cache: FeatureCache) -> None:
        self.pairs = pairs
        self.cache = cache
        root = pairs.data
        self._names = {_key(ref): episode_name(root, ref) for ref, _ in frames_needed(pairs)}
        self._labels = {
            _key(ref): torch.from_numpy(pairs.trajectory(ref))
            for agent, demo, _ in pairs.pairs
            for ref in (agent, demo)
        }
        self._contacts = (
            {
                _key(ref): torch.from_numpy(pairs.contact(ref))
                for agent, demo, _ in pairs.pairs
                for ref in (agent, demo)
            }
            if pairs.contact_points
            else {}
        )

    def __len__(self) -> int:
        return len(self.pairs)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        agent, demo, head = self.pairs.pairs[index]
        demo_idx = demo_frame_indices(demo.steps, self.pairs.demo_frames)
        first = self.cache.features(self._names[_key(agent)], np.zeros(1, np.int64))
        sample = {
            "demo_features": self.cache.features(self._names[_key(demo)], demo_idx),
            "first_frame_features": first[0],
            "trajectory": self._labels[_key(agent)],
            "demo_trajectory": self._labels[_key(demo)],
            "head": torch.tensor(head, dtype=torch.int64),
            "camera": torch.tensor(self.pairs.pair_camera[index], dtype=torch.int64),
        }
        if self._contacts:
            sample["contact"] = self._contacts[_key(agent)]
            sample["demo_contact"] = self._contacts[_key(demo)]
        return sample


def tosvi_frames_needed(samples: TosviDataset) -> list[tuple[EpisodeRef, np.ndarray]]:
    """Every episode the T-OSVI samples read, with the sorted state indices they read of it: the
    agent stacks of every sample (all steps of an episode: states 0 .. T-1; state T, after the
    last action, is in no stack); a demonstrator's demo frames; both for self-paired synthesized
    episodes."""
    refs: dict[tuple[str, str], EpisodeRef] = {}
    needed: dict[tuple[str, str], set[int]] = {}
    demos_done: set[tuple[str, str]] = set()
    for agent, demo, t in samples.samples:
        key = _key(agent)
        refs[key] = agent
        needed.setdefault(key, set()).update(int(i) for i in samples.stack_indices(t))
        key = _key(demo)
        if key not in demos_done:
            demos_done.add(key)
            refs[key] = demo
            idx = demo_frame_indices(demo.steps, samples.demo_frames)
            needed.setdefault(key, set()).update(int(i) for i in idx)
    return [(refs[k], np.array(sorted(v), dtype=np.int64)) for k, v in needed.items()]


class CachedTosviSamples:
    """``samples`` with feature maps from ``cache`` (module docstring)."""

    def __init__(self, samples: TosviDataset, cache: FeatureCache) -> None:
        self.samples = samples
        self.cache = cache
        root = samples.data
        self._names = {
            _key(ref): episode_name(root, ref) for ref, _ in tosvi_frames_needed(samples)
        }
        agents = {_key(agent): agent for agent, _, _ in samples.samples}
        self._actions = {k: torch.from_numpy(root.actions(ref)) for k, ref in agents.items()}

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        agent, demo, t = self.samples.samples[index]
        stack = self.samples.stack_indices(t)
        demo_idx = demo_frame_indices(demo.steps, self.samples.demo_frames)
        sample = {
            "demo_features": self.cache.features(self._names[_key(demo)], demo_idx),
            "frame_features": self.cache.features(self._names[_key(agent)], stack),
            "actions": self._actions[_key(agent)][torch.from_numpy(stack)],
        }
        if self.samples.with_depth:
            sample["depth"] = self.samples.depth_stack(agent, stack)
        return sample
