"""The agent cameras a cell head votes on the rays of: how a config lists them, how a scene's
camera is matched to one of them.

A suite's third-person camera is fixed per scene, not per suite: MOSAIC films door and drawer from
one side and its other five families from another. A network trained on such a suite holds every
camera its training samples were filmed with (``AwdaConfig.camera_*``, in order of first
appearance), and each sample, or live scene, names the one it was filmed with by its index.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from awda_bench.models.cell_readout import Camera
    from awda_bench.models.config import AwdaConfig

CameraMatrices = tuple[np.ndarray, np.ndarray]
"""``(intrinsic_cv (3, 3), world-to-camera extrinsic_cv (3, 4))``, OpenCV conventions."""

INTRINSIC_ATOL = 1e-2
"""Two cameras are one when their intrinsics agree to this [px] ..."""

EXTRINSIC_ATOL = 1e-3
"""... and their extrinsics to this [m, and rotation entries]."""


def same_camera(a: CameraMatrices, b: CameraMatrices) -> bool:
    """Whether ``a`` and ``b`` are the same camera (within :data:`INTRINSIC_ATOL`,
    :data:`EXTRINSIC_ATOL`)."""
    return bool(
        np.allclose(a[0], b[0], atol=INTRINSIC_ATOL)
        and np.allclose(a[1], b[1], atol=EXTRINSIC_ATOL)
    )


def camera_index(cameras: Sequence[CameraMatrices], camera: CameraMatrices) -> int | None:
    """The index of ``camera`` among ``cameras``, or ``None``."""
    for i, known in enumerate(cameras):
        if same_camera(known, camera):
            return i
    return None


def config_cameras(config: AwdaConfig) -> list[CameraMatrices]:
    """The cameras ``config`` lists (empty: free xyz votes)."""
    k = np.asarray(config.camera_intrinsic, dtype=np.float64).reshape(-1, 3, 3)
    e = np.asarray(config.camera_extrinsic, dtype=np.float64).reshape(-1, 3, 4)
    return list(zip(k, e, strict=True))


def config_ray_cameras(config: AwdaConfig) -> tuple[Camera, ...]:
    """``config``'s cameras as the cell readout takes them (torch, with the image size)."""
    import torch

    height, width = (int(v) for v in config.camera_size) if config.camera_size else (0, 0)
    return tuple(
        (torch.from_numpy(k.copy()), torch.from_numpy(e.copy()), (height, width))
        for k, e in config_cameras(config)
    )


def camera_fields(cameras: Sequence[CameraMatrices], size: Sequence[int]) -> dict[str, Any]:
    """The ``camera_*`` fields of :class:`~awda_bench.models.config.AwdaConfig` for ``cameras``
    (in this order) filming ``size`` = ``(height, width)`` [px] images; plain floats and ints,
    so a snapshot stores them as JSON."""
    return {
        "camera_intrinsic": tuple(float(v) for k, _ in cameras for v in np.ravel(k)),
        "camera_extrinsic": tuple(float(v) for _, e in cameras for v in np.ravel(e)),
        "camera_size": tuple(int(v) for v in size),
    }
