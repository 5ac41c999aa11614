"""Frozen-backbone features of a collection's frames, encoded once and kept on disk.

When a recipe freezes the backbone (``model.freeze_backbone = true``), a training step never needs
the images, only their feature maps: ``train`` encodes every frame its datasets read once, here,
and the loop runs the attention layers and heads over the cached maps (a few percent of a step
through the backbone). Evaluation encodes each live frame with the same frozen backbone, which the
snapshot carries, so training and evaluation see the same features.

Where and what::

    DATA_DIR/features/<key>.h5      key = sha256(format version, collection fingerprint, backbone,
                                                 stride, weights, image size, variant, and the
                                                 fine-tuned top blocks when there are)[:16]
        attrs: key, meta (JSON of what the key hashes), complete (written last)
        <unit path>/<traj>/indices   (n,) int64           state indices encoded
        <unit path>/<traj>/features  (n, C, h, w) float16 the backbone's map of each, fletcher32

Changing the trunk, its stage or the image size gives another key, hence another file. The file
is written as ``<key>.h5.partial`` (episodes appended; an interrupted build resumes where it
stopped) and renamed when complete; a dataset needing episodes or frames the file lacks
(validation pairs of the same collection; T-OSVI's agent stacks, every frame 0..T-1 of an agent
episode, where AWDA read only o_1) adds them the same way: an episode holds the union of the
frames every dataset asked of it, so datasets sharing a key never evict each other. Every
dataset carries HDF5's Fletcher-32 checksum, and the frames a dataset reads are read into memory
when it opens the cache: a damaged file (truncated, flipped bytes, missing episodes) is found
then, reported on one line, deleted and rebuilt, never read as data.

Size (float16): a 240x320 frame's stride-16 EfficientNet-Lite0 map (112 x 15 x 20) is 67 KB;
T-OSVI's 2x2-pooled map (112 x 8 x 10) 18 KB, 18.5 MB per 1,000 frames on disk (measured).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import signal
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import torch

from awda_bench.data.datasets import CollectedData, EpisodeRef, frames_tensor
from awda_bench.errors import CorruptFileError
from awda_bench.models.config import TrunkConfig
from awda_bench.models.frame_encoder import frozen_encoder

log = logging.getLogger(__name__)

FORMAT_VERSION = 2
"""Bumped whenever what a cache file holds changes meaning. 2: encoded by
:func:`~awda_bench.models.frame_encoder.frozen_encoder` (eval-mode batch norm) only; version-1
files could hold training-mode features from a caller's encoder and are never read."""

CACHE_DIR = "features"
"""Sub-directory of DATA_DIR holding the caches."""

ENCODE_BATCH = 32
"""Frames per backbone call while encoding."""

Encoder = Callable[[torch.Tensor], torch.Tensor]
"""RGB ``(N, 3, H, W)`` in [0, 1] -> features ``(N, C, h, w)``."""


def cache_meta(fingerprint: str, trunk: TrunkConfig, variant: str = "rgb") -> dict[str, Any]:
    """What a cache's key is the hash of."""
    meta: dict[str, Any] = {
        "format": FORMAT_VERSION,
        "collection": fingerprint,
        "backbone": trunk.backbone,
        "stride": trunk.backbone_stride,
        "weights": trunk.backbone_weights,
        "image_size": [trunk.image_height_px, trunk.image_width_px],
        "variant": variant,
    }
    if trunk.finetune_top_blocks:  # the map entering the trained top blocks (absent: the stage's)
        meta["top_blocks_trained"] = trunk.finetune_top_blocks
    return meta


def cache_key(meta: Mapping[str, Any]) -> str:
    blob = json.dumps(dict(meta), sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def cache_path(root: Path, fingerprint: str, trunk: TrunkConfig, variant: str = "rgb") -> Path:
    """The file that holds (or will hold) the cache of collection ``root`` (whose fingerprint is
    ``fingerprint``) for ``trunk`` and ``variant``."""
    return root / CACHE_DIR / f"{cache_key(cache_meta(fingerprint, trunk, variant))}.h5"


def episode_name(data: CollectedData, ref: EpisodeRef) -> str:
    """The group an episode's features live in."""
    return f"{ref.file.relative_to(data.root).with_suffix('').as_posix()}/{ref.traj}"


class FeatureCache:
    """The in-memory features of one cache file: ``features(ref, indices) -> (n, C, h, w)``."""

    def __init__(self, path: Path, entries: dict[str, tuple[np.ndarray, torch.Tensor]]) -> None:
        self.path = path
        self._entries = entries

    def __len__(self) -> int:
        return len(self._entries)

    def features(self, name: str, indices: np.ndarray) -> torch.Tensor:
        """float32 ``(len(indices), C, h, w)`` for the episode ``name`` at state ``indices``."""
        try:
            stored, maps = self._entries[name]
        except KeyError as exc:
            raise CorruptFileError(
                f"feature cache {self.path} lacks episode {name}; delete the file, "
                "train rebuilds it"
            ) from exc
        rows = np.searchsorted(stored, indices)
        if np.any(rows >= len(stored)) or np.any(
            stored[np.minimum(rows, len(stored) - 1)] != indices
        ):
            raise CorruptFileError(
                f"feature cache {self.path} lacks frames {indices.tolist()} of {name}; delete "
                "the file, train rebuilds it"
            )
        return maps[torch.from_numpy(rows)].float()


class _MissingEpisodes(Exception):
    """A sound cache file that lacks episodes another dataset of the collection needs."""


def _read(path: Path, key: str, wanted: Mapping[str, np.ndarray]) -> FeatureCache:
    """Read and check a complete cache file; any defect raises :class:`CorruptFileError`."""
    entries: dict[str, tuple[np.ndarray, torch.Tensor]] = {}
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("key") != key or not f.attrs.get("complete"):
                raise CorruptFileError(f"feature cache {path} is incomplete or has another key")
            if any(name not in f for name in wanted):
                raise _MissingEpisodes(path)
            for name, indices in wanted.items():
                group = f[name]
                stored = np.asarray(group["indices"][()], dtype=np.int64)
                if np.any(np.diff(stored) <= 0):
                    raise CorruptFileError(f"feature cache {path}: {name} has unsorted indices")
                if not np.all(np.isin(indices, stored)):
                    raise _MissingEpisodes(path)
                if np.array_equal(stored, indices):
                    maps = np.asarray(group["features"][()])
                else:  # the file holds more of this episode than this dataset reads
                    rows = np.searchsorted(stored, indices)
                    maps = np.asarray(group["features"][rows])
                entries[name] = (indices, torch.from_numpy(maps))
    except (CorruptFileError, _MissingEpisodes):
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:  # fletcher32 mismatch is an OSError
        raise CorruptFileError(
            f"feature cache {path} is damaged ({type(exc).__name__}: {exc})"
        ) from exc
    return FeatureCache(path, entries)


def _encode_into(
    path: Path,
    key: str,
    meta: Mapping[str, Any],
    data: CollectedData,
    refs: Mapping[str, tuple[EpisodeRef, np.ndarray]],
    encoder: Encoder,
    image_size: tuple[int, int],
    progress: bool,
) -> None:
    """Append every missing episode's features to the partial file ``path`` (an episode that
    lacks some of the frames asked for is encoded again, with the union of both). The file is
    flushed after every episode and closed on SIGTERM (:func:`_closing_on_sigterm`), so a
    stopped build resumes where it stopped."""
    from tqdm import tqdm

    with h5py.File(path, "a") as f, _closing_on_sigterm():
        if f.attrs.get("key") not in (None, key):
            raise CorruptFileError(f"partial feature cache {path} has another key")
        f.attrs["key"] = key
        f.attrs["meta"] = json.dumps(dict(meta), sort_keys=True)
        todo: dict[str, np.ndarray] = {}
        for name, (_, wanted) in refs.items():
            if name in f and f[name].attrs.get("done"):
                stored = np.asarray(f[name]["indices"][()], dtype=np.int64)
                if np.all(np.isin(wanted, stored)):
                    continue
                wanted = np.union1d(stored, wanted)
            todo[name] = wanted
        frames_total = sum(len(i) for i in todo.values())
        bar = tqdm(total=frames_total, disable=not progress, unit="frame", desc="encode features")
        for name, indices in todo.items():
            ref = refs[name][0]
            images = frames_tensor(data.frames(ref, indices), image_size)
            with torch.no_grad():
                maps = torch.cat(
                    [
                        encoder(images[i : i + ENCODE_BATCH])
                        for i in range(0, len(images), ENCODE_BATCH)
                    ]
                )
            if name in f:
                del f[name]
            group = f.create_group(name)
            group.create_dataset("indices", data=indices, fletcher32=True)
            group.create_dataset("features", data=maps.half().numpy(), fletcher32=True, chunks=True)
            group.attrs["done"] = True
            f.flush()  # on disk episode by episode: a process killed later leaves it readable
            bar.update(len(indices))
        bar.close()
        f.attrs["complete"] = True


@contextlib.contextmanager
def _closing_on_sigterm() -> Iterator[None]:
    """While open: SIGTERM (``reproduce`` stopping a stage, a cluster's scheduler) exits with
    status 143 through ``SystemExit``, so the ``with`` around it closes the HDF5 file. Python's
    default dies at once, and an HDF5 file left open is unreadable: a stopped T-OSVI build lost
    its partial cache that way (session 45). Off the main thread (where no handler can be set)
    nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, _frame: object) -> None:
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def load_or_build(
    data: CollectedData,
    trunk: TrunkConfig,
    frames: Sequence[tuple[EpisodeRef, np.ndarray]],
    encoder: Encoder | None = None,
    *,
    variant: str = "rgb",
    progress: bool = True,
) -> FeatureCache:
    """The cache of ``frames`` ((episode, sorted state indices) pairs) for ``trunk`` over ``data``:
    read when present and sound, otherwise (re)built first with ``trunk``'s
    :func:`~awda_bench.models.frame_encoder.frozen_encoder`. ``encoder`` replaces it: a function
    of that encoder's output (T-OSVI's pooled maps, under their own ``variant``) or a test's
    stand-in; whatever it computes is stored under the trunk's key."""
    meta = cache_meta(data.fingerprint, trunk, variant)
    key = cache_key(meta)
    path = cache_path(data.root, data.fingerprint, trunk, variant)
    folder = path.parent
    refs = {episode_name(data, ref): (ref, np.asarray(idx, np.int64)) for ref, idx in frames}
    wanted = {name: idx for name, (_, idx) in refs.items()}
    partial = path.with_name(path.name + ".partial")
    if path.is_file():
        try:
            return _read(path, key, wanted)
        except _MissingEpisodes:  # another dataset of this collection: encode what it adds
            os.replace(path, partial)
        except CorruptFileError as exc:
            log.warning("%s; rebuilding it", exc)
            path.unlink()
    folder.mkdir(exist_ok=True)
    size = (trunk.image_height_px, trunk.image_width_px)
    if encoder is None:
        encoder = frozen_encoder(trunk)
    try:
        _encode_into(partial, key, meta, data, refs, encoder, size, progress)
    except (OSError, CorruptFileError) as exc:  # a damaged partial file: start it again
        log.warning("partial feature cache %s unusable (%s); encoding again", partial, exc)
        partial.unlink(missing_ok=True)
        _encode_into(partial, key, meta, data, refs, encoder, size, progress)
    os.replace(partial, path)
    return _read(path, key, wanted)
