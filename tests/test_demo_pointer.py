"""The ``demo-pointer`` head and its identification loss: content, not place; the object to grasp
identified by appearance, so an unseen (object, destination) pairing is found."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from awda_bench.errors import UsageError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.cell_readout import CellHeadShape, DemoHeights, HandPath
from awda_bench.models.config import AwdaConfig, TrunkConfig
from awda_bench.models.demo_pointer import DemoPointer
from awda_bench.models.identification_loss import (
    demo_frame_points,
    grasp_cells,
    hand_loss,
    height_loss,
    place_loss,
    release_cells,
)

K = np.array([[219.66, 0.0, 160.0], [0.0, 219.66, 120.0], [0.0, 0.0, 1.0]])
E = np.array(
    [[0.0, 1.0, 0.0, 0.0], [0.8396, 0.0, -0.5433, 0.1007], [-0.5433, 0.0, -0.8396, 0.7447]]
)


CAMERA = {
    "camera_intrinsic": tuple(K.ravel()),
    "camera_extrinsic": tuple(E.ravel()),
    "camera_size": (240, 320),
}
"""AwdaConfig's camera fields of the test camera."""
POINTER_TRUNK = TrunkConfig(
    backbone="efficientnet-lite0", backbone_stride=16, freeze_backbone=True,
    head="demo-pointer", attention_head_dim=8,
)  # fmt: skip


def _grasping_batch() -> dict[str, torch.Tensor]:
    """Two cached-feature rows whose trajectories grasp from point 4 on (seeded)."""
    torch.manual_seed(0)
    trajectory = torch.zeros(2, 10, 4)
    trajectory[:, :, :3] = torch.tensor([-0.1, 0.05, 0.02])
    trajectory[:, 4:, 3] = 1.0
    return {
        "demo_features": torch.randn(2, 10, 112, 15, 20),
        "first_frame_features": torch.randn(2, 112, 15, 20),
        "trajectory": trajectory,
        "demo_trajectory": trajectory,
        "head": torch.zeros(2, dtype=torch.long),
    }


def _shape(grid: tuple[int, int], frames: int) -> CellHeadShape:
    return CellHeadShape(
        channels=8, grid=grid, demo_frames=frames, dim=16, dropout=0.0, hidden=32,
        waypoints=5, waypoint_dim=4, num_heads=2,
    )  # fmt: skip


def test_the_demo_pointer_points_by_content_not_by_place() -> None:
    """Moving everything the demo and o_1 show by a few cells moves every waypoint's score, the
    what-moved logits and the object logits over the cells by the same cells: the head has no
    absolute position to memorize scenes by (``demo-to-scene``, which has, does not pass this)."""
    torch.manual_seed(0)
    grid, dy, dx = (12, 16), 2, 3
    head = DemoPointer(_shape(grid, 4)).eval()
    with torch.no_grad():
        head.readout.prior_weight.normal_()  # the object logits take part in every score
    demo = torch.zeros(1, 4, 8, *grid)
    first = torch.zeros(1, 8, *grid)
    # content in the middle, empty cells around it
    demo[..., 3:7, 4:9] = torch.randn(1, 4, 8, 4, 5)
    first[..., 3:7, 4:9] = torch.randn(1, 8, 4, 5)

    def scores(demo: torch.Tensor, first: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            x, moved, found = head.tokens(demo, first)[:3]
            where = (
                head.readout.where_logits[1](x) + found[..., None] * head.readout.prior_weight[1]
            )
            return torch.cat((where, moved[..., None], found[..., None]), -1).view(*grid, 7)

    p = scores(demo, first)
    q = scores(*(torch.roll(x, (dy, dx), dims=(-2, -1)) for x in (demo, first)))
    # the same scores, moved; compared off the image's edge cells (the 3x3 convolutions pad there)
    torch.testing.assert_close(q[2 + dy : -2, 2 + dx : -2], p[2 : -2 - dy, 2 : -2 - dx])
    assert float(p.std()) > 0.05  # scores that differ between cells


def _scenes(pairs: list[tuple[int, int]], n: int, seed: int) -> tuple[torch.Tensor, ...]:
    """Synthetic demos: four object kinds (fixed feature vectors) at random cells of rows 0-3, four
    compartments in row 5; the demo carries object ``k`` into compartment ``j`` over its frames;
    o_1 shows the four kinds at other random cells. Labels: the object's cell in the demo's first
    frame and in o_1."""
    g = torch.Generator().manual_seed(seed)
    kinds = torch.randn(4, 8, generator=torch.Generator().manual_seed(123)) * 2
    compartment = torch.randn(8, generator=torch.Generator().manual_seed(7))
    h, w, frames = 6, 8, 5
    demo = 0.1 * torch.randn(n, frames, 8, h, w, generator=g)
    first = 0.1 * torch.randn(n, 8, h, w, generator=g)
    demo[:, :, :, 5, 1::2] += compartment[None, None, :, None]
    demo_cell, first_cell = torch.empty(n, dtype=torch.long), torch.empty(n, dtype=torch.long)
    for i in range(n):
        k, j = pairs[int(torch.randint(len(pairs), (1,), generator=g))]
        demo_cells = torch.randperm(4 * w, generator=g)[:4]
        first_cells = torch.randperm(4 * w, generator=g)[:4]
        for kind in range(4):
            r, c = divmod(int(first_cells[kind]), w)
            first[i, :, r, c] += kinds[kind]
            r, c = divmod(int(demo_cells[kind]), w)
            if kind != k:
                demo[i, :, :, r, c] += kinds[kind]
                continue
            for t in range(frames):  # carried from (r, c) to compartment j
                a = t / (frames - 1)
                rt, ct = round(r + a * (5 - r)), round(c + a * (2 * j + 1 - c))
                demo[i, t, :, rt, ct] += kinds[kind]
        demo_cell[i], first_cell[i] = demo_cells[k], first_cells[k]
    return demo, first, demo_cell, first_cell


def test_identification_finds_the_object_of_an_unseen_pairing() -> None:
    """Trained with the identification loss on 14 (object, compartment) pairings, the head finds
    the object of the two held-out pairings (object 3 into compartments 2 and 3: the pick-place
    suite's held-out tasks) in o_1: it identifies by appearance, not by where the object went."""
    torch.manual_seed(0)
    held_out = [(3, 2), (3, 3)]
    seen = [(k, j) for k in range(4) for j in range(4) if (k, j) not in held_out]
    head = DemoPointer(_shape((6, 8), 5))
    opt = torch.optim.Adam(head.parameters(), 3e-3)
    for step in range(150):
        demo, first, demo_cell, first_cell = _scenes(seen, 32, seed=step)
        _, moved, found = head.tokens(demo, first)[:3]
        loss = F.cross_entropy(moved, demo_cell) + F.cross_entropy(found, first_cell)
        opt.zero_grad()
        loss.backward()
        opt.step()
    head.eval()
    demo, first, _, first_cell = _scenes(held_out, 200, seed=10_000)
    with torch.no_grad():
        found = head.tokens(demo, first)[2]
    assert float((found.argmax(1) == first_cell).float().mean()) >= 0.9


def test_grasp_cells_project_the_first_grasping_point() -> None:
    camera = (torch.tensor(K), torch.tensor(E), (240, 320))
    point = np.array([-0.1, 0.05, 0.02])
    cam = E[:, :3] @ point + E[:, 3]
    u, v = (K @ cam)[:2] / cam[2]
    want = int(v // 16) * 20 + int(u // 16)
    trajectory = torch.zeros(2, 6, 4, dtype=torch.float32)
    trajectory[:, :, :3] = torch.tensor([0.3, 0.3, 0.3])  # elsewhere, not grasping
    trajectory[0, 2:, :3] = torch.tensor(point, dtype=torch.float32)
    trajectory[0, 2:, 3] = 1.0  # grasps from point 2 on
    cells, grasps = grasp_cells(trajectory, camera, (15, 20))
    assert int(cells[0]) == want
    assert grasps.tolist() == [True, False]  # row 1 never grasps: no label


def test_a_row_without_a_grasp_takes_its_contact_point() -> None:
    """Meta-World's pushes: the contact point labels the rows that never grasp; a grasp keeps
    precedence; a row with neither (or with an unset flag) stays out."""
    camera = (torch.tensor(K), torch.tensor(E), (240, 320))

    def cell(point: np.ndarray) -> int:
        cam = E[:, :3] @ point + E[:, 3]
        u, v = (K @ cam)[:2] / cam[2]
        return int(v // 16) * 20 + int(u // 16)

    grasp_point, touched = np.array([-0.1, 0.05, 0.02]), np.array([0.1, -0.05, 0.05])
    trajectory = torch.zeros(3, 6, 4, dtype=torch.float32)
    trajectory[:, :, :3] = torch.tensor([0.3, 0.3, 0.3])
    trajectory[0, 2:, :3] = torch.tensor(grasp_point, dtype=torch.float32)
    trajectory[0, 2:, 3] = 1.0  # row 0 grasps
    contact = torch.zeros(3, 4)
    contact[:2, :3] = torch.tensor(touched, dtype=torch.float32)
    contact[:2, 3] = 1.0  # rows 0 and 1 touch; row 2 has no contact
    cells, ok = grasp_cells(trajectory, camera, (15, 20), contact)
    assert ok.tolist() == [True, True, False]
    assert [int(c) for c in cells[:2]] == [cell(grasp_point), cell(touched)]
    assert cell(grasp_point) != cell(touched)
    without, ok_without = grasp_cells(trajectory, camera, (15, 20))
    assert ok_without.tolist() == [True, False, False] and int(without[0]) == int(cells[0])


def test_identification_weight_needs_the_pointer_and_a_camera() -> None:
    camera, pointer = CAMERA, POINTER_TRUNK
    with pytest.raises(UsageError, match="identification_weight"):
        AwdaConfig(trunk=pointer, identification_weight=1.0)  # no camera
    with pytest.raises(UsageError, match="identification_weight"):
        AwdaConfig(trunk=TrunkConfig(head="demo-to-scene"), identification_weight=1.0, **camera)
    config = AwdaConfig(trunk=pointer, identification_weight=1.0, **camera)
    model = AwdaNet(config, load_backbone_weights=False)
    batch = _grasping_batch()
    loss, info = model.compute_loss(batch)
    assert info["id_rows"] == 1.0 and info["id_moved"] > 0 and info["id_object"] > 0
    loss.backward()
    assert model.scene_head is not None
    assert model.scene_head.moved[0].weight.grad is not None  # the what-moved convs learn


def test_demo_frame_points_read_the_tcp_at_each_demo_frame() -> None:
    """Frame i of Td spans the episode as point i (P - 1) / (Td - 1) of the trajectory does."""
    points = torch.zeros(1, 10, 4)
    points[0, :, 0] = torch.arange(10, dtype=torch.float32)  # x = the point's index
    at = demo_frame_points(points, 4)  # frames at points 0, 3, 6, 9
    torch.testing.assert_close(at[0, :, 0], torch.tensor([0.0, 3.0, 6.0, 9.0]))
    at = demo_frame_points(points, 7)  # points 0, 1.5, 3, ... interpolated
    torch.testing.assert_close(at[0, :, 0], torch.arange(7, dtype=torch.float32) * 1.5)


def test_the_hand_path_moves_the_demo_hands_path_onto_o1s_object() -> None:
    """With its weight up, a waypoint's softmax peaks at o_1's object cell shifted by where the
    demo's hand was relative to the demo's moved object (the phase it attends to); the hand loss
    labels each demo frame with its TCP's cell and trains the hand convolutions."""
    torch.manual_seed(0)
    grid = (6, 8)
    shape = CellHeadShape(
        channels=8, grid=grid, demo_frames=3, dim=16, dropout=0.0, hidden=32,
        waypoints=5, waypoint_dim=4, num_heads=2, hand_path=True,
    )  # fmt: skip
    head = DemoPointer(shape).eval()
    readout = head.readout
    xy = readout.cell_xy
    # the demo's hand: at cell 9 while the demo's object is at cell 20; o_1's object at cell 33
    relative = (xy[9] - xy[20]).expand(1, 3, 2)
    path = HandPath(relative, xy[33][None])
    x = torch.zeros(1, 48, 16)
    with torch.no_grad():
        readout.path_weight.fill_(50.0)
        p = readout.where(x, 0, prior=torch.zeros(1, 48), path=path)
    target = xy[33] + xy[9] - xy[20]
    want = int((xy - target).square().sum(-1).argmin())
    assert p[0].argmax(0).tolist() == [want] * 5
    with pytest.raises(ValueError, match="hand_path"):
        readout.where(x, 0, prior=torch.zeros(1, 48))
    # the whole head: the hand logits per demo frame, the loss through them
    out = head.pointer(torch.randn(2, 3, 8, *grid), torch.randn(2, 8, *grid), torch.zeros(2).long())
    assert out.hand_logits is not None and out.hand_logits.shape == (2, 3, 48)
    camera = (torch.tensor(K), torch.tensor(E), (240, 320))
    demo = torch.zeros(2, 10, 4)
    demo[:, :, :3] = torch.tensor([-0.1, 0.05, 0.02])
    loss, info = hand_loss(out.hand_logits, demo, [camera], None, grid)
    assert info["id_hand"] > 0
    loss.backward()
    assert head.hand is not None and head.hand[0].weight.grad is not None


def test_the_hand_path_trains_with_the_identification_loss() -> None:
    camera, pointer = CAMERA, POINTER_TRUNK
    with pytest.raises(UsageError, match="demo_hand_path"):
        AwdaConfig(trunk=pointer, demo_hand_path=True, **camera)  # no identification loss
    config = AwdaConfig(trunk=pointer, identification_weight=1.0, demo_hand_path=True, **camera)
    model = AwdaNet(config, load_backbone_weights=False)
    batch = _grasping_batch()
    loss, info = model.compute_loss(batch)
    assert info["id_hand"] > 0 and info["id_rows"] == 1.0
    loss.backward()
    assert model.scene_head is not None and model.scene_head.readout.path_weight.grad is not None
    with torch.no_grad():  # inference goes through the path too
        out = model.forward_features(
            batch["demo_features"], batch["first_frame_features"], batch["head"]
        )
    assert out.shape == (2, 15, 4) and bool(torch.isfinite(out).all())


def _apart(h: int, w: int, g: torch.Generator) -> torch.Tensor:
    """Three random cells of an ``h x w`` grid, each two or more cells from the others."""
    while True:
        cells = torch.randperm(h * w, generator=g)[:3]
        r, c = cells // w, cells % w
        gap = torch.maximum((r[:, None] - r).abs(), (c[:, None] - c).abs())
        if int((gap + 9 * torch.eye(3, dtype=torch.long)).min()) >= 2:
            return cells


def _stacks(
    pairs: list[tuple[int, int]], n: int, seed: int, kinds: int = 3
) -> tuple[torch.Tensor, ...]:
    """Synthetic stacking demos over ``kinds`` cube kinds (fixed feature vectors): each scene
    shows the carried kind ``a``, the base kind ``b`` and one more at random cells of a 6 x 8
    grid, two or more cells apart (the scenes keep their cubes 11 cm apart, 3-5 cells); the demo
    carries ``a`` onto ``b``, which stays where it is; o_1 shows the three at other such cells.
    Labels: ``b``'s cell in the demo and in o_1."""
    g = torch.Generator().manual_seed(seed)
    features = torch.randn(kinds, 8, generator=torch.Generator().manual_seed(321)) * 2
    h, w, frames = 6, 8, 5
    demo = 0.1 * torch.randn(n, frames, 8, h, w, generator=g)
    first = 0.1 * torch.randn(n, 8, h, w, generator=g)
    put_cell, target_cell = torch.empty(n, dtype=torch.long), torch.empty(n, dtype=torch.long)
    for i in range(n):
        a, b = pairs[int(torch.randint(len(pairs), (1,), generator=g))]
        others = [k for k in range(kinds) if k not in (a, b)]
        shown = (a, b, others[int(torch.randint(len(others), (1,), generator=g))])
        demo_cells, first_cells = _apart(h, w, g), _apart(h, w, g)
        rb, cb = divmod(int(demo_cells[1]), w)
        for j, kind in enumerate(shown):
            r, c = divmod(int(first_cells[j]), w)
            first[i, :, r, c] += features[kind]
            r, c = divmod(int(demo_cells[j]), w)
            if j:
                demo[i, :, :, r, c] += features[kind]
                continue
            for t in range(frames):  # carried from (r, c) onto the base
                f = t / (frames - 1)
                demo[i, t, :, round(r + f * (rb - r)), round(c + f * (cb - c))] += features[kind]
        put_cell[i], target_cell[i] = demo_cells[1], first_cells[1]
    return demo, first, put_cell, target_cell


def _place_found(
    head: DemoPointer, seen: list[tuple[int, int]], held_out: list[tuple[int, int]], kinds: int
) -> float:
    """Train ``head``'s put and target softmaxes on ``seen`` pairs (200 steps of 32), then the
    fraction of 300 ``held_out`` scenes whose target softmax peaks on the base."""
    opt = torch.optim.Adam(head.parameters(), 3e-3)
    for step in range(200):
        demo, first, put_cell, target_cell = _stacks(seen, 32, step, kinds)
        tokens = head.tokens(demo, first)
        assert tokens.put is not None and tokens.target is not None
        loss = F.cross_entropy(tokens.put, put_cell) + F.cross_entropy(tokens.target, target_cell)
        opt.zero_grad()
        loss.backward()
        opt.step()
    head.eval()
    demo, first, _, target_cell = _stacks(held_out, 300, 10_000, kinds)
    with torch.no_grad():
        target = head.tokens(demo, first).target
    assert target is not None
    return float((target.argmax(1) == target_cell).float().mean())


def test_the_place_target_finds_the_destination_of_an_unseen_pairing() -> None:
    """Trained on five of the six (cube, onto cube) orders, the place target finds the base cube
    of the sixth in o_1, whose cubes stand elsewhere than the demo's: it identifies the place
    by appearance, as the object is identified."""
    torch.manual_seed(0)
    held_out = [(2, 0)]
    seen = [(a, b) for a in range(3) for b in range(3) if a != b and (a, b) not in held_out]
    shape = CellHeadShape(
        channels=8, grid=(6, 8), demo_frames=5, dim=16, dropout=0.0, hidden=32,
        waypoints=5, waypoint_dim=4, num_heads=2, place_target=True,
    )  # fmt: skip
    head = DemoPointer(shape)
    assert _place_found(head, seen, held_out, kinds=3) >= 0.9
    demo, first, _, _ = _stacks(held_out, 2, 0)
    # the readout takes both priors, and only a place-target readout takes two
    with torch.no_grad():
        out = head.pointer(demo[:2], first[:2], torch.zeros(2).long())
    assert out.target_logits is not None and out.waypoints.shape == (2, 5, 4)
    with pytest.raises(ValueError, match="place_target"):
        head.readout.where(torch.zeros(1, 48, 16), 0, prior=torch.zeros(1, 48))
    plain = DemoPointer(_shape((6, 8), 5))
    with pytest.raises(ValueError, match="place_target"):
        plain.readout.where(torch.zeros(1, 48, 16), 0, prior=torch.zeros(1, 48, 2))


def test_release_cells_project_the_last_grasping_point_of_a_trajectory_that_lets_go() -> None:
    camera = (torch.tensor(K), torch.tensor(E), (240, 320))
    point = np.array([-0.05, -0.1, 0.08])
    cam = E[:, :3] @ point + E[:, 3]
    u, v = (K @ cam)[:2] / cam[2]
    trajectory = torch.zeros(3, 8, 4, dtype=torch.float32)
    trajectory[:, :, :3] = torch.tensor([0.3, 0.3, 0.3])
    trajectory[:, 2:6, 3] = 1.0  # rows 0 and 1 grasp at points 2-5, row 1 never lets go
    trajectory[1, 6:, 3] = 1.0
    trajectory[2, :, 3] = 0.0  # row 2 never grasps
    trajectory[0, 5, :3] = torch.tensor(point, dtype=torch.float32)  # where row 0 lets go
    cells, ok = release_cells(trajectory, camera, (15, 20))
    assert ok.tolist() == [True, False, False]
    assert int(cells[0]) == int(v // 16) * 20 + int(u // 16)


def test_the_place_loss_labels_task_rows_that_let_go() -> None:
    """Through the whole network: the place target needs the identification loss; its loss
    counts the task-driven rows whose demo and trajectory let go, not the synthesized ones."""
    camera, pointer = CAMERA, POINTER_TRUNK
    with pytest.raises(UsageError, match="place_target"):
        AwdaConfig(trunk=pointer, place_target=True, **camera)  # no identification loss
    config = AwdaConfig(trunk=pointer, identification_weight=1.0, place_target=True, **camera)
    model = AwdaNet(config, load_backbone_weights=False)
    batch = _grasping_batch()
    batch["trajectory"][:, 8:, 3] = 0.0  # let go at point 7
    batch["demo_trajectory"] = batch["trajectory"]
    batch["head"] = torch.tensor([0, 1])  # row 1 is synthesized
    loss, info = model.compute_loss(batch)
    assert info["id_place_rows"] == 0.5 and info["id_put"] > 0 and info["id_target"] > 0
    loss.backward()
    assert model.scene_head is not None and model.scene_head.put is not None
    assert model.scene_head.put[0].weight.grad is not None
    assert model.scene_head.readout.target_weight.grad is not None
    batch["head"] = torch.tensor([1, 1])  # no task rows: a zero place loss, still a graph
    zero, _ = place_loss(
        torch.zeros(2, 300, requires_grad=True), torch.zeros(2, 300), batch["demo_trajectory"],
        batch["trajectory"], batch["head"], model.ray_cameras, None, model.grid,
    )  # fmt: skip
    assert float(zero) == 0.0 and zero.requires_grad


def test_the_place_targets_cosine_finds_a_kind_of_target_never_trained_on() -> None:
    """Leave-one-family-out in miniature: bases of kinds 0-5 in training, of kinds 6 and 7 held
    out. Scored by the cosine between o_1's cells and the demo's target (``place_match``, cells
    not neighbourhoods), the held-out bases are found well above the ~1/3 of a guess among the
    three shown (0.71 measured; a learned score over pooled neighbourhoods found 0.00)."""
    torch.manual_seed(0)
    train = [(a, b) for a in range(8) for b in range(6) if a != b]
    held_out = [(a, b) for a in range(6) for b in (6, 7)]
    shape = CellHeadShape(
        channels=8, grid=(6, 8), demo_frames=5, dim=16, dropout=0.0, hidden=32, waypoints=5,
        waypoint_dim=4, num_heads=2, place_target=True, place_pool=False, place_match=True,
    )  # fmt: skip
    head = DemoPointer(shape)
    assert head.target_logit is None and head.target_match is not None
    assert _place_found(head, train, held_out, kinds=8) >= 0.6


def test_demo_heights_carry_the_demos_hand_height_into_every_waypoint() -> None:
    """With ``demo_heights`` a waypoint's height follows the demo's hand heights: raising every
    demo frame's height by 7 cm raises every waypoint by 7 cm (the cells' own votes unchanged);
    a waypoint picks its frame by what the frame shows, wherever it stands in the demo; and a
    readout built with them refuses to run without."""
    torch.manual_seed(0)
    grid = (6, 8)
    camera = (torch.tensor(K), torch.tensor(E), (240, 320))
    shape = CellHeadShape(
        channels=8, grid=grid, demo_frames=4, dim=16, dropout=0.0, hidden=32,
        waypoints=5, waypoint_dim=4, num_heads=2, cameras=(camera,), demo_heights=True,
    )  # fmt: skip
    readout = DemoPointer(shape).readout.eval()
    with torch.no_grad():
        readout.height_phase.normal_()  # each waypoint its own blend of the frames
    x, head = torch.randn(2, 48, 16), torch.tensor([0, 1])
    prior = torch.zeros(2, 48)
    frames = torch.randn(2, 4, 16)
    heights = 0.1 * torch.rand(2, 4)
    with torch.no_grad():
        low = readout(x, head, prior=prior, heights=DemoHeights(heights, frames))
        high = readout(x, head, prior=prior, heights=DemoHeights(heights + 0.07, frames))
    assert torch.allclose(high[..., 2] - low[..., 2], torch.full((2, 5), 0.07), atol=1e-5)
    assert not torch.allclose(high[..., :2], low[..., :2])  # each point moved along its ray
    # every waypoint looks for the frame that shows feature 0: frame 1 in one demo, 3 in another
    with torch.no_grad():
        readout.height_phase.zero_()
        for when in readout.height_when:
            when.weight.zero_()
            when.bias.zero_()
            when.weight[:, 0] = 50.0
    marked = torch.zeros(2, 4, 16)
    marked[0, 1, 0] = marked[1, 3, 0] = 1.0
    zeta = torch.tensor([[0.02, 0.30, 0.05, 0.10], [0.02, 0.30, 0.05, 0.10]])
    head = torch.zeros(2, dtype=torch.long)
    with torch.no_grad():
        out = readout(x[:1].expand(2, -1, -1), head, prior=prior, heights=DemoHeights(zeta, marked))
    torch.testing.assert_close(
        out[0, :, 2] - out[1, :, 2], torch.full((5,), 0.20), atol=1e-4, rtol=0
    )
    with pytest.raises(ValueError, match="demo_heights"):
        readout(x, head, prior=prior)


@pytest.mark.parametrize(("unit_m", "taken_m"), [(0.05, 0.02), (1.0, 0.08)])
def test_demo_heights_choice_reads_heights_in_its_unit(unit_m: float, taken_m: float) -> None:
    """By height alone, a modest weight (-4 per unit) makes every waypoint take the demo's lowest
    frame, 3 cm below the next, when the choice reads heights in 5-cm units; in metres (the unit
    before session 44) the same weight blends all four frames (0.08 m)."""
    torch.manual_seed(0)
    camera = (torch.tensor(K), torch.tensor(E), (240, 320))
    shape = CellHeadShape(
        channels=8, grid=(6, 8), demo_frames=4, dim=16, dropout=0.0, hidden=32, waypoints=5,
        waypoint_dim=4, num_heads=1, cameras=(camera,), demo_heights=True, height_unit_m=unit_m,
    )  # fmt: skip
    readout = DemoPointer(shape).readout.eval()
    cells, head = torch.randn(1, 48, 16).expand(2, -1, -1), torch.zeros(2).long()
    prior, blank = torch.zeros(2, 48), torch.zeros(2, 4, 16)
    deep = torch.tensor([[0.30, 0.02, 0.05, 0.10], [0.30, 0.05, 0.02, 0.10]])
    with torch.no_grad():
        readout.height_phase.zero_()
        readout.height_when[0].weight.zero_()
        readout.height_when[0].bias.zero_()
        readout.height_when[0].weight[:, -1] = -4.0
        taken = readout(cells, head, prior=prior, heights=DemoHeights(deep, blank))
        floor = readout(cells, head, prior=prior, heights=DemoHeights(torch.zeros(2, 4), blank))
    torch.testing.assert_close(
        taken[..., 2] - floor[..., 2], torch.full((2, 5), taken_m), atol=5e-3, rtol=0
    )


def test_demo_heights_train_with_the_identification_loss() -> None:
    """The height loss labels the hand height read off each demo frame (where the hand loss says
    the hand is) with the demonstrator's TCP z there; its gradient reaches the hand, the height
    regression and the per-waypoint blend, and the config asks for the identification loss it
    shares a weight with."""
    with pytest.raises(UsageError, match="demo_heights"):
        AwdaConfig(trunk=POINTER_TRUNK, demo_heights=True, **CAMERA)
    config = AwdaConfig(trunk=POINTER_TRUNK, identification_weight=1.0, demo_heights=True, **CAMERA)
    model = AwdaNet(config, load_backbone_weights=False)
    batch = _grasping_batch()
    loss, info = model.compute_loss(batch)
    assert info["id_height"] > 0 and info["id_height_err_cm"] > 0 and info["id_hand"] > 0
    loss.backward()
    head = model.scene_head
    assert isinstance(head, DemoPointer) and head.hand is not None
    assert head.height_value is not None and head.height_value[0].weight.grad is not None
    assert head.hand[0].weight.grad is not None
    assert head.readout.height_phase.grad is not None
    # a perfect reading costs nothing: heights equal to the TCP z at each demo frame
    truth = demo_frame_points(batch["demo_trajectory"], 10)[..., 2]
    zero, _ = height_loss(truth, batch["demo_trajectory"])
    assert float(zero) == 0.0
