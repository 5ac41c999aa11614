"""A trained network loaded from a snapshot for a learned policy: the arch checked, the model built
on the device, and the JPEG quality its training frames were stored at (live frames are compressed
the same way first: :func:`awda_bench.data.trajectory_file.as_stored`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Generic, TypeVar

from awda_bench.data.trajectory_file import trained_jpeg_quality
from awda_bench.errors import CorruptFileError

Model = TypeVar("Model")


@dataclass(frozen=True)
class TrainedModel(Generic[Model]):
    """What a learned policy needs of its snapshot."""

    model: Model
    """The network, built on :attr:`device` from the snapshot's weights."""
    arch: str
    """The snapshot's architecture (``awda``, ``tosvi``, ``tosvi-depth``)."""
    device: str
    """``cuda`` where available, else ``cpu``."""
    jpeg_quality: int
    """Live frames are JPEG-compressed at this quality first, as the training frames were."""


def load_trained(
    snapshot: str | Path, archs: tuple[str, ...], model_type: type[Model], fix: str
) -> TrainedModel[Model]:
    """``snapshot``'s network, which must be one of ``archs`` and build a ``model_type``; a
    snapshot of another arch is refused with ``fix`` (what to pick instead)."""
    import torch

    from awda_bench.models.snapshot import load_snapshot

    loaded = load_snapshot(Path(snapshot))
    if loaded.arch not in archs:
        wanted = " or ".join(repr(a) for a in archs)
        raise CorruptFileError(
            f"snapshot {snapshot} holds a {loaded.arch!r} model, not {wanted}; {fix}"
        )
    device = "cuda" if torch.cuda.is_available() else "cpu"
    model = loaded.build_model(device)
    if not isinstance(model, model_type):
        raise CorruptFileError(f"snapshot {snapshot} did not build a {model_type.__name__}")
    return TrainedModel(model, loaded.arch, device, trained_jpeg_quality(loaded.training))
