"""Is there a Vulkan device SAPIEN can render with? Checked once, before any env is built.

ManiSkill 3.0.1 needs a render device even for ``obs_mode="state"``, so every command that builds
an env calls :func:`require_renderer` first and fails with one line and the fix instead of a SAPIEN
traceback. Without a GPU the device is Mesa's lavapipe, which SAPIEN accepts from Mesa 24.3 on.
"""

from __future__ import annotations

import functools
import re
import shutil
import subprocess
from dataclasses import dataclass

from awda_bench.errors import RendererUnavailableError

FIX = (
    "SAPIEN found no Vulkan device it can render with (needs a GPU driver or Mesa lavapipe >= 24.3); "
    "fix: run 'bash scripts/setup.sh' (on Debian 12 it installs mesa-vulkan-drivers from "
    "bookworm-backports) and check that VK_ICD_FILENAMES, if set, points to an existing ICD file"
)
"""The one-line message every command prints when rendering is impossible."""


@dataclass(frozen=True)
class RenderDevice:
    """What SAPIEN renders on."""

    name: str
    """Device name as SAPIEN reports it, e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)``."""
    software: bool
    """True for a CPU rasterizer (lavapipe/llvmpipe), False for a GPU."""
    mesa_version: str | None
    """Installed Mesa Vulkan driver version (from the package manager), when known."""

    @property
    def label(self) -> str:
        kind = "lavapipe (CPU, software Vulkan)" if self.software else "GPU"
        mesa = f", Mesa {self.mesa_version}" if self.mesa_version else ""
        return f"{kind}: {self.name}{mesa}"


def _mesa_version() -> str | None:
    if shutil.which("dpkg-query") is None:
        return None
    result = subprocess.run(
        ["dpkg-query", "-W", "-f=${Version}", "mesa-vulkan-drivers"],
        capture_output=True,
        text=True,
        check=False,
    )
    if result.returncode != 0 or not result.stdout:
        return None
    return re.sub(r"^\d+:", "", result.stdout.strip())


@functools.cache
def probe_render_device() -> RenderDevice:
    """Ask SAPIEN for its render device; :class:`RendererUnavailableError` if there is none."""
    import sapien

    try:
        summary = sapien.render.get_device_summary()
        sapien.render.RenderSystem()
    except RuntimeError as exc:
        raise RendererUnavailableError(f"{FIX} (SAPIEN: {exc})") from exc
    names = re.findall(r"GPU:\s*(.+)", summary)
    name = names[0].strip() if names else summary.strip().splitlines()[0]
    software = any(word in name.lower() for word in ("llvmpipe", "lavapipe", "swiftshader"))
    return RenderDevice(
        name=name, software=software, mesa_version=_mesa_version() if software else None
    )


def render_backend() -> str:
    """ManiSkill ``render_backend`` for this machine: ``"gpu"`` with CUDA, else ``"cpu"`` (what
    ManiSkill would fall back to anyway, minus its warning on every env built)."""
    import torch

    return "gpu" if torch.cuda.is_available() else "cpu"


def require_renderer() -> RenderDevice:
    """Raise :class:`RendererUnavailableError` (one line, with the fix) unless SAPIEN can render."""
    return probe_render_device()
