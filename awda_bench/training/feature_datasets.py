"""AWDA pairs served from a frozen backbone's feature cache instead of images.

:class:`CachedAwdaPairs` yields the same pairs, in the same order, as the
:class:`~awda_bench.data.datasets.AwdaPairDataset` it wraps, with the images replaced by their
cached feature maps (:mod:`awda_bench.training.feature_cache`)::

    "demo_features"        (demo_frames, C, h, w) float32
    "first_frame_features" (C, h, w) float32
    "trajectory", "demo_trajectory", "head"   as AwdaPairDataset

Labels are read once and kept in memory (the episode files are not touched again).
"""

from __future__ import annotations

import numpy as np
import torch

from awda_bench.data.datasets import AwdaPairDataset, EpisodeRef, demo_frame_indices
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

    def __len__(self) -> int:
        return len(self.pairs)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        agent, demo, head = self.pairs.pairs[index]
        demo_idx = demo_frame_indices(demo.steps, self.pairs.demo_frames)
        first = self.cache.features(self._names[_key(agent)], np.zeros(1, np.int64))
        return {
            "demo_features": self.cache.features(self._names[_key(demo)], demo_idx),
            "first_frame_features": first[0],
            "trajectory": self._labels[_key(agent)],
            "demo_trajectory": self._labels[_key(demo)],
            "head": torch.tensor(head, dtype=torch.int64),
        }
