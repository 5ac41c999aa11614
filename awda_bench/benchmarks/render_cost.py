"""``python -m awda_bench bench render-cost``: where a rendered frame's time goes, per render body.

On lavapipe (Mesa's CPU Vulkan) a frame costs ~25-35 ms whatever its size (SPEC §1), which is most
of a closed-loop policy's episode (``bench episode-cost``). This benchmark takes one suite scene
(``--task``, reset with seed 0; ``--embodiment`` picks the agent's robot or the
demonstrator's) and times ``camera.capture()`` (the render; ``update_render`` and the
read-back cost ~0.01 and ~0.2 ms) with

- the whole scene visible;
- nothing visible (the fixed cost of a frame);
- each render body alone visible: its triangle count and what it adds to the fixed cost.

Hiding is ``RenderBodyComponent.visibility = 0``, which the renderer culls (a hidden scene costs
what a scene without render bodies does).

``--decimate RATIO`` (repeatable) also measures the robot's visual meshes simplified to
``RATIO`` of their triangles (quadric decimation: ``trimesh``'s ``simplify_quadric_decimation``,
which needs the ``fast-simplification`` package), side by side with the original meshes in the
same scene (both attached, one visible at a time, timed in alternating rounds), and how far the
image moves: mean absolute pixel difference and the share of pixels off by more than 16 of 255.
With ``--out DIR`` it writes ``DIR/render-cost-decimate-RATIO.png`` (original | decimated |
difference x4). This is a measurement only: no suite renders decimated meshes, and a policy
trained on the original frames has not seen decimated ones.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.errors import UsageError

DIFF_THRESHOLD = 16
"""A pixel counts as changed when one of its channels moves by more than this (of 255)."""


def add_render_cost_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--suite", default="pick_place", help="suite (default pick_place)")
    parser.add_argument("--task", type=int, default=0, help="task of the timed scene (default 0)")
    parser.add_argument(
        "--embodiment",
        choices=("agent", "demonstrator"),
        default="agent",
        help="whose robot the scene holds (default agent: the Panda the policies drive)",
    )
    parser.add_argument(
        "--camera",
        default=None,
        help="sensor uid (default: the policy's third-person camera; 'hand_camera' is the wrist's)",
    )
    parser.add_argument("--frames", type=int, default=30, help="captures per timing (median)")
    parser.add_argument(
        "--decimate",
        type=float,
        action="append",
        default=[],
        metavar="RATIO",
        help="also time the robot's visual meshes decimated to RATIO of their triangles "
        "(repeatable; needs fast-simplification)",
    )
    parser.add_argument("--out", type=Path, default=None, help="write comparison images here")


def _render_bodies(env: Any) -> list[tuple[str, Any]]:
    """``(entity name, RenderBodyComponent)`` of sub-scene 0, in scene order."""
    import sapien

    scene = env.unwrapped.scene.sub_scenes[0]
    return [
        (entity.name, component)
        for entity in scene.entities
        for component in entity.components
        if isinstance(component, sapien.render.RenderBodyComponent)
    ]


def _triangles(body: Any) -> int:
    return sum(len(part.get_triangles()) for shape in body.render_shapes for part in shape.parts)


def _capture_ms(env: Any, sensor: Any, frames: int) -> float:
    """Median wall time of ``frames`` captures [ms], after syncing the scene to the renderer."""
    env.unwrapped.scene.update_render()
    times = []
    for _ in range(frames):
        start = time.perf_counter()
        sensor.capture()
        times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times))


def _show(bodies: list[tuple[str, Any]], visible: set[int]) -> None:
    for index, (_, body) in enumerate(bodies):
        body.visibility = 1.0 if index in visible else 0.0


def _decimated_body(body: Any, ratio: float) -> Any:
    """A new render body with ``body``'s shapes, each part simplified to ``ratio`` of its triangles
    (parts under 1,000 triangles are kept), same materials, poses and scales, flat-shaded like the
    mesh files (every triangle its own three vertices and its face normal)."""
    import sapien
    import trimesh

    out = sapien.render.RenderBodyComponent()
    for shape in body.render_shapes:
        for part in shape.parts:
            mesh = trimesh.Trimesh(part.get_vertices(), part.get_triangles(), process=False)
            if len(mesh.faces) >= 1000:
                mesh.merge_vertices()  # the mesh files split vertices at hard edges
                mesh = mesh.simplify_quadric_decimation(percent=1.0 - ratio)
                mesh.fix_normals()
            # flat shading, as the mesh files are (every triangle its own three vertices)
            vertices = np.asarray(mesh.vertices[mesh.faces].reshape(-1, 3), dtype=np.float32)
            normals = np.repeat(np.asarray(mesh.face_normals, dtype=np.float32), 3, axis=0)
            new = sapien.render.RenderShapeTriangleMesh(
                vertices,
                np.arange(len(vertices), dtype=np.uint32).reshape(-1, 3),
                normals,
                np.zeros((len(vertices), 2), dtype=np.float32),
                part.material,
            )
            new.local_pose = shape.local_pose
            new.scale = shape.scale
            out.attach(new)
    return out


def _robot_entities(env: Any) -> set[str]:
    """Entity names of the scene robot's links (the agent's or the demonstrator's)."""
    return {link.name for link in env.unwrapped.agent.robot.get_links()}


def _compare_decimated(env: Any, sensor: Any, capture: Any, ratio: float, args: Any) -> str:
    """Attach decimated copies of the robot's bodies beside the originals; time and diff both."""
    robot = _robot_entities(env)
    originals = [(n, b) for n, b in _render_bodies(env) if n in robot]
    if not originals:
        raise UsageError("this scene's robot has no render bodies to decimate")
    copies = []
    for _, body in originals:
        copy = _decimated_body(body, ratio)
        body.entity.add_component(copy)
        copies.append(copy)

    def use(decimated: bool) -> None:
        for body, copy in zip((b for _, b in originals), copies, strict=True):
            body.visibility, copy.visibility = (0.0, 1.0) if decimated else (1.0, 0.0)

    timings: dict[bool, list[float]] = {False: [], True: []}
    for _ in range(3):  # alternating rounds, so a busy moment hits both alike
        for decimated in (False, True):
            use(decimated)
            timings[decimated].append(_capture_ms(env, sensor, args.frames))
    use(False)
    before = capture()
    use(True)
    after = capture()
    use(False)
    for body, copy in zip((b for _, b in originals), copies, strict=True):
        body.entity.remove_component(copy)
    diff = np.abs(before.astype(np.int16) - after.astype(np.int16))
    tris = sum(_triangles(b) for _, b in originals), sum(_triangles(c) for c in copies)
    full, low = float(np.median(timings[False])), float(np.median(timings[True]))
    line = (
        f"robot decimated to {ratio:g}: {tris[0]} -> {tris[1]} triangles; frame {full:.1f} -> "
        f"{low:.1f} ms ({full / low:.2f}x faster); image: mean |diff| {diff.mean():.2f}/255, "
        f"{100 * (diff.max(-1) > DIFF_THRESHOLD).mean():.2f} % of pixels off by > "
        f"{DIFF_THRESHOLD}"
    )
    if args.out is not None:
        import cv2

        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / f"render-cost-decimate-{ratio:g}.png"
        panel = np.concatenate([before, after, np.clip(diff * 4, 0, 255).astype(np.uint8)], 1)
        cv2.imwrite(str(path), cv2.cvtColor(panel, cv2.COLOR_RGB2BGR))
        line += f"; {path}"
    return line


def run_render_cost_bench(args: argparse.Namespace) -> int:
    import torch

    from awda_bench.demo_recording import make_demo_env
    from awda_bench.evaluation.episode_runner import fresh_scene_options
    from awda_bench.robot.cameras import THIRD_PERSON_CAMERA, camera_sensor, capture_rgb
    from awda_bench.suites import load_suite

    torch.set_num_threads(1)
    if args.frames < 1:
        raise UsageError(f"--frames must be at least 1 (got {args.frames})")
    for ratio in args.decimate:
        if not 0.0 < ratio < 1.0:
            raise UsageError(f"--decimate takes a ratio in (0, 1), e.g. 0.1 (got {ratio})")
    if args.decimate:
        try:
            import fast_simplification  # noqa: F401  (trimesh's decimation backend)
        except ModuleNotFoundError as exc:
            raise UsageError(
                "--decimate needs the fast-simplification package: pip install "
                "fast-simplification (or the dev extra)"
            ) from exc
    suite = load_suite(args.suite)
    if suite.simulator != "maniskill":
        raise UsageError(f"render-cost measures SAPIEN scenes; suite {suite.name!r} is not one")
    if not 0 <= args.task < len(suite.tasks):
        raise UsageError(f"--task must be in 0..{len(suite.tasks) - 1} (got {args.task})")
    uid = args.camera or THIRD_PERSON_CAMERA
    env = make_demo_env(suite, args.embodiment, env_id=suite.env_id_for(args.task))
    env.reset(seed=0, options=fresh_scene_options(suite, args.task))
    sensor = camera_sensor(env, uid)
    first = capture_rgb(env, uid)  # builds the render pipeline (seconds)
    bodies = _render_bodies(env)

    def capture() -> np.ndarray:
        return capture_rgb(env, uid)[0]  # syncs the scene to the renderer itself

    _show(bodies, set())
    fixed = _capture_ms(env, sensor, args.frames)
    rows = []
    for index, (name, body) in enumerate(bodies):
        _show(bodies, {index})
        rows.append((name, _triangles(body), _capture_ms(env, sensor, args.frames) - fixed))
    _show(bodies, set(range(len(bodies))))
    whole = _capture_ms(env, sensor, args.frames)
    h, w = first.shape[1:3]
    print(
        f"{suite.name} task {args.task} ({args.embodiment}: {env.unwrapped.robot_uids}), camera "
        f"{uid} {h}x{w}: median of {args.frames} captures, 1 torch thread"
    )
    print(f"whole scene {whole:.1f} ms a frame; nothing visible {fixed:.1f} ms (fixed cost)")
    print(f"{'render body (alone)':<32} {'triangles':>9} {'+ms':>7}")
    for name, tris, extra in sorted(rows, key=lambda r: -r[2]):
        print(f"{name:<32} {tris:>9} {extra:>7.2f}")
    robot = _robot_entities(env)
    robot_ms = sum(extra for name, _, extra in rows if name in robot)
    robot_tris = sum(tris for name, tris, _ in rows if name in robot)
    print(
        f"robot: {robot_tris} triangles, {robot_ms:.1f} ms of the bodies' "
        f"{sum(r[2] for r in rows):.1f} ms (each alone; together {whole - fixed:.1f} ms)"
    )
    for ratio in args.decimate:
        print(_compare_decimated(env, sensor, capture, ratio, args))
    env.close()
    return 0
