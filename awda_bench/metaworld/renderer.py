"""One MuJoCo renderer per process: any named camera of the current model, RGB and depth.

Two renderers in one process (one per env, as gymnasium's ``MujocoEnv`` makes them) give blank or
wrong frames unless each context is made current before every frame; here one GL context serves
every env of the process, and the model-side context (textures, meshes) is rebuilt only when the
model changes (a worker's episodes come sorted by task). Frames come in any size up to the
model's offscreen buffer (640x480 in Meta-World).

Speed: the models ask for 4x multisampling (``vis.quality.offsamples``), shadows and reflections,
which cost ~140 ms a 224x224 frame on Mesa's software renderer; without them ~20 ms (both
measured in one run, ``python -m awda_bench.benchmarks.metaworld_frames``). :data:`FAST`
switches them off.

Camera frames (OpenCV convention: x right, y down, z forward)::

    MuJoCo camera: x right, y up, looks along -z      R_cv = R_gl @ diag(1, -1, -1)
    intrinsics: f = (H / 2) / tan(fovy / 2) [px], cx = W / 2, cy = H / 2
    upside-down cameras (image "up" pointing down in the world: Meta-World's corner cameras)
    are rotated 180 degrees: pixels (W - u, H - v), R_cv' = R_cv @ diag(-1, -1, 1)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

FAST = True
"""Render without multisampling, shadows and reflections (see the module docstring)."""

MAX_GEOMS = 10_000
"""Geoms a scene can hold (MuJoCo's ``Renderer`` default)."""


@dataclass(frozen=True)
class CameraFrame:
    """One capture of a named camera."""

    rgb: np.ndarray | None
    """``(H, W, 3)`` uint8, upright; ``None`` when not asked for."""
    depth_m: np.ndarray | None
    """``(H, W)`` float32 depth along the optical axis [m], 0 where nothing was hit; ``None``
    when not asked for."""
    intrinsic_cv: np.ndarray
    """``(3, 3)`` float64 pinhole intrinsics of the (upright) image [px]."""
    cam2world_cv: np.ndarray
    """``(4, 4)`` float64 camera-to-world transform, OpenCV axes, of the upright image."""


def camera_id(model: Any, name: str) -> int:
    """The id of camera ``name``; a one-line error listing the model's cameras."""
    index = int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name))
    if index < 0:
        names = [model.camera(i).name for i in range(model.ncam)]
        raise ValueError(f"unknown camera {name!r}; choose one of: {', '.join(names)}")
    return index


def camera_pose(
    model: Any, data: Any, name: str, height: int, width: int
) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(intrinsic_cv, cam2world_cv, upside_down)`` of camera ``name`` for an upright image of
    ``height`` x ``width`` px (``data`` after ``mj_forward``)."""
    index = camera_id(model, name)
    fovy = np.deg2rad(float(model.cam_fovy[index]))
    f = 0.5 * height / np.tan(0.5 * fovy)
    intrinsic = np.array([[f, 0.0, 0.5 * width], [0.0, f, 0.5 * height], [0.0, 0.0, 1.0]])
    r_gl = np.asarray(data.cam_xmat[index], dtype=np.float64).reshape(3, 3)
    upside_down = bool(r_gl[2, 1] < 0.0)  # the image's "up" (camera +y) points down in the world
    r_cv = r_gl @ np.diag([1.0, -1.0, -1.0])
    if upside_down:
        r_cv = r_cv @ np.diag([-1.0, -1.0, 1.0])
    cam2world = np.eye(4)
    cam2world[:3, :3] = r_cv
    cam2world[:3, 3] = np.asarray(data.cam_xpos[index], dtype=np.float64)
    return intrinsic, cam2world, upside_down


class FrameRenderer:
    """Renders cameras of one model at a time on this process's single GL context."""

    def __init__(self, fast: bool = FAST) -> None:
        self.fast = fast
        self._gl: Any = None
        self._model: Any = None
        self._context: Any = None
        self._scene: Any = None
        self._option: Any = None

    def _bind(self, model: Any) -> None:
        """Make ``model`` the one rendered (a new model-side context if it changed)."""
        if self._gl is None:
            self._gl = mujoco.GLContext(
                int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
            )
        self._gl.make_current()
        if model is self._model:
            return
        self._free_model()
        if self.fast:
            model.vis.quality.offsamples = 0  # read when the offscreen buffer is made
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=MAX_GEOMS)
        if self.fast:
            self._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            self._scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        self._option = mujoco.MjvOption()
        self._model = model

    def capture(
        self,
        model: Any,
        data: Any,
        camera: str,
        *,
        height: int,
        width: int,
        rgb: bool = True,
        depth: bool = False,
    ) -> CameraFrame:
        """Render ``camera`` of ``model`` in state ``data`` (after ``mj_forward``)."""
        self._bind(model)
        intrinsic, cam2world, upside_down = camera_pose(model, data, camera, height, width)
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        cam.fixedcamid = camera_id(model, camera)
        mujoco.mjv_updateScene(
            model, data, self._option, None, cam, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        rect = mujoco.MjrRect(0, 0, width, height)
        mujoco.mjr_render(rect, self._scene, self._context)
        pixels = np.empty((height, width, 3), dtype=np.uint8) if rgb else None
        z = np.empty((height, width), dtype=np.float32) if depth else None
        mujoco.mjr_readPixels(pixels, z, rect, self._context)
        turn = 2 if upside_down else 0  # 180 degrees, else none; rows come bottom-up: flip
        if pixels is not None:
            pixels = np.ascontiguousarray(np.rot90(np.flipud(pixels), turn))
        depth_m = None
        if z is not None:
            depth_m = np.ascontiguousarray(np.rot90(np.flipud(metres(model, z)), turn))
        return CameraFrame(pixels, depth_m, intrinsic, cam2world)

    def _free_model(self) -> None:
        if self._context is not None:
            self._context.free()
        self._context = self._scene = self._option = self._model = None

    def close(self) -> None:
        """Free the model context and the GL context (the process may render again later)."""
        if self._gl is not None:
            self._gl.make_current()
            self._free_model()
            self._gl.free()
        self._gl = None


def metres(model: Any, z: np.ndarray) -> np.ndarray:
    """OpenGL depth-buffer values (``mjDEPTH_ZEROFAR``: 0 at the far plane) to depth along the
    optical axis [m], 0 where nothing was hit (MuJoCo's ``Renderer`` formula)."""
    extent = float(model.stat.extent)
    near = float(model.vis.map.znear) * extent
    far = float(model.vis.map.zfar) * extent
    c = 0.5 * (far + near) / (far - near) - 0.5
    d = (far * near) / (far - near)
    z64 = z.astype(np.float64)
    depth = d / (z64 + c)
    depth[(z64 <= 0.0) | (depth >= far * (1.0 - 1e-6))] = 0.0
    return depth.astype(np.float32)


_RENDERER: FrameRenderer | None = None


def process_renderer() -> FrameRenderer:
    """This process's renderer, made on first use."""
    global _RENDERER
    if _RENDERER is None:
        _RENDERER = FrameRenderer()
    return _RENDERER
