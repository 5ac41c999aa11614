"""The method's 4-D action, shared by every embodiment: checks and meaning.

``action[..., 0:3]`` in [-1, 1] is the TCP displacement for one control step as a fraction of the
controller's ``max_step_m``; ``action[..., 3] > 0`` closes the gripper, ``<= 0`` opens it.
"""

from __future__ import annotations

import numpy as np
import torch

ACTION_DIM = 4
"""dx, dy, dz, grip."""


def validate_action(action: object, num_envs: int, dim: int = ACTION_DIM) -> torch.Tensor:
    """Return ``action`` as a float tensor of shape ``(num_envs, dim)``, or raise ``ValueError``.

    A ``(dim,)`` action is accepted when ``num_envs == 1``. NaN or infinite entries are refused
    (never turned into joint targets); finite values outside [-1, 1] are clipped downstream.
    """
    if isinstance(action, torch.Tensor):
        tensor = action
    else:
        try:
            tensor = torch.as_tensor(np.asarray(action, dtype=np.float32))
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"action must be numeric with shape ({num_envs}, {dim}): {exc}"
            ) from exc
    if tensor.ndim == 1 and num_envs == 1:
        tensor = tensor[None]
    if tuple(tensor.shape) != (num_envs, dim):
        raise ValueError(
            f"action must have shape ({num_envs}, {dim}) (dx, dy, dz, grip per env), got {tuple(tensor.shape)}"
        )
    if not bool(torch.isfinite(tensor).all()):
        raise ValueError(
            "action contains NaN or inf; every entry must be a finite number in [-1, 1]"
        )
    return tensor.float()
