"""Local observations and messages (docs/model.md, Local observations and messages): each UAV's observation checked
against a loop written here over the positions, tasks, nodes and messages; nothing beyond a UAV's range changes it."""

from __future__ import annotations

import math

import pytest
import torch
from torchrl.envs.utils import check_env_specs

from uavrl.envs import InvalidOption, UAVSpectrumEnv, World, make_config
from uavrl.envs.limits import OWN_FEATURES, VERTICAL_FEATURES

MODELS = {
    "paper": dict(preset="paper", grid=(6, 5), num_uavs=4),
    "random_layout": dict(preset="paper", grid=(5, 5), num_uavs=3, layout="random"),
    "levels": dict(preset="a2g_urban", grid=(4, 4), num_uavs=3, altitudes_m=[50.0, 100.0, 200.0]),
    "energy": dict(preset="a2g_urban", grid=(5, 5), num_uavs=3, energy="rotary_wing", base=(-1, 0), recharge_steps=2),
}


def expected_observation(world: World, out: dict, messages: torch.Tensor | None, central: torch.Tensor) -> torch.Tensor:
    """Each UAV's local observation by loops: its own part (the central observation's), each node and other UAV
    within the radius as docs/model.md writes it."""
    cfg = world.cfg
    B, N = out["tasks"].shape
    L1, L2 = cfg.grid
    radius = cfg.comm_radius_cells
    levels = cfg.num_levels > 1
    energy = cfg.energy != "none"
    heights = cfg.level_heights
    cells = world.state.cell
    nodes = world.nodes
    rows = []
    for b in range(B):
        for i in range(N):
            own_size = OWN_FEATURES
            row = list(central[b, i, :own_size])
            points = [
                (*(float(v) for v in out["positions"][b, j]), heights[int(out["levels"][b, j]) if levels else 0])
                for j in range(N)
            ]
            serving = [int(cells[b, j]) < world.num_positions for j in range(N)]
            me = points[i]
            for node in nodes[b]:
                d = [float(node[k]) - me[k] for k in range(3)]
                if serving[i] and math.dist(node.tolist(), me) <= radius:
                    row += [d[0] / L1, d[1] / L2, d[2] / cfg.height, 1.0]
                else:
                    row += [0.0] * 4
            if energy:  # the central observation's own battery and service flag follow the others' (x, y, task)
                start = OWN_FEATURES + 3 * (N - 1)
                row += list(central[b, i, start : start + 2])
            if levels:
                start = OWN_FEATURES + 3 * (N - 1) + (2 * N if energy else 0)
                row += list(central[b, i, start : start + VERTICAL_FEATURES])

            for k in range(1, N):
                j = (i + k) % N
                other = points[j]
                size = 4 + 2 * energy + levels + cfg.message_size
                if not (serving[i] and serving[j] and math.dist(other, me) <= radius):
                    row += [0.0] * size
                    continue
                row += [(other[0] - me[0]) / max(L1 - 1, 1), (other[1] - me[1]) / max(L2 - 1, 1)]
                row += [float(out["tasks"][b, j]), 1.0]
                if energy:
                    features = world.energy_features(out["state"])[b, j]
                    row += [float(v) for v in features]
                if levels:
                    row.append((int(out["levels"][b, j]) - int(out["levels"][b, i])) / (cfg.num_levels - 1))
                if cfg.message_size:  # zeros after a reset
                    row += [0.0] * cfg.message_size if messages is None else [float(v) for v in messages[b, j]]
            rows.append(row)
    return torch.tensor(rows, dtype=torch.float32).view(B, N, -1)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("radius", [0.0, 1.0, 2.5, None])
def test_local_observations_match_a_loop_over_what_each_uav_hears(model, radius):
    kw = dict(MODELS[model])
    preset = kw.pop("preset")
    if radius is not None and preset != "paper":
        radius *= kw.get("cell_size", 50.0)  # metres under a physical channel
    message_size = 2 if radius != 0.0 else 0
    local_cfg = make_config(preset, observation="local", comm_radius=radius, message_size=message_size, **kw)
    local, central = World(local_cfg, batch_size=3, seed=5), World(make_config(preset, **kw), batch_size=3, seed=5)
    out, central_out = local.reset(), central.reset()
    gen = torch.Generator().manual_seed(0)
    messages = None
    for _ in range(4):
        expected = expected_observation(local, out, messages, central_out["observation"])
        torch.testing.assert_close(out["observation"], expected, rtol=0, atol=1e-6)
        assert out["observation"].shape[-1] == local.observation_size
        torch.testing.assert_close(out["state"], central_out["state"], rtol=0, atol=0)
        action = torch.randint(0, local_cfg.num_actions - (local_cfg.recharge_steps is not None), (3, 3), generator=gen)
        action = action[:, : local.num_uavs] if local.num_uavs <= 3 else torch.randint(0, 6, (3, local.num_uavs))
        messages = 2 * torch.rand(3, local.num_uavs, message_size, generator=gen) - 1 if message_size else None
        out, _, _ = local.step(action, messages)
        central_out, _, _ = central.step(action)


def perturbed_out_of_range(code: torch.Tensor, messages: torch.Tensor, grid, radius: float, gen) -> tuple:
    """``(code, messages)`` of one world ``[N]``, ``[N, d]`` with every UAV beyond ``radius`` cells of UAV 0 moved to
    another free cell beyond it, its task switched and its message negated; the rest as they were."""
    L1, L2 = grid
    xy = torch.stack([(code >> 1) % L1, (code >> 1) // L1], -1).double()
    near = (xy - xy[0]).norm(dim=-1) <= radius
    far_cells = [c for c in range(L1 * L2) if math.dist((c % L1, c // L1), xy[0].tolist()) > radius]
    far_cells = torch.tensor(far_cells)[torch.randperm(len(far_cells), generator=gen)]
    far_cells = far_cells[~torch.isin(far_cells, code >> 1)][: int((~near).sum())]
    moved = code.clone()
    moved[~near] = 2 * far_cells + (1 - (code[~near] & 1))
    return moved, torch.where(near[:, None], messages, -messages)


def test_out_of_range_changes_leave_a_uavs_observation_as_it_was():
    """UAV 0's observation reads nothing beyond its range: moving the UAVs out of its range to other cells out of
    range, switching their tasks and changing their messages leave it as it was; under ``central`` the same changes
    change it (this test can fail).  The nodes stay: what a UAV measures of their signals at its cell and the next
    ones is its own radio's, not a message (docs/model.md, Local observations and messages)."""
    kw = dict(grid=(8, 8), num_uavs=5)
    local = World(make_config("paper", observation="local", comm_radius=2.0, message_size=2, **kw), batch_size=1)
    central = World(make_config("paper", **kw), batch_size=1)
    gen = torch.Generator().manual_seed(1)
    changed_central = 0
    for _ in range(200):
        code = 2 * torch.randperm(64, generator=gen)[:5] + torch.randint(0, 2, (5,), generator=gen)
        messages = 2 * torch.rand(5, 2, generator=gen) - 1
        moved, heard = perturbed_out_of_range(code, messages, (8, 8), 2.0, gen)
        before = local.configurations(code[None], messages=messages[None])["observation"][0, 0]
        after = local.configurations(moved[None], messages=heard[None])["observation"][0, 0]
        assert torch.equal(before, after)
        seen = [central.configurations(c[None])["observation"][0, 0] for c in (code, moved)]
        changed_central += not torch.equal(*seen)
    assert changed_central > 100


def test_a_message_reaches_those_within_range_at_the_next_step():
    env = UAVSpectrumEnv(batch_size=2, grid=(6, 6), num_uavs=3, observation="local", comm_radius=1.5, message_size=2)
    check_env_specs(env)
    td = env.reset()
    td["agents", "action"] = torch.randint(0, 6, (2, 3))
    td["agents", "message"] = torch.tensor([[0.5, -0.25], [3.0, -3.0], [0.0, 1.0]]).expand(2, 3, 2).clone()
    out = env.step(td)["next"]
    positions = out["positions"].double()
    for b in range(2):
        for i in range(3):
            for k in (1, 2):
                j = (i + k) % 3
                slot = out["agents", "observation"][b, i, 29 + 6 * (k - 1) : 29 + 6 * k]  # own 13, nodes 16
                heard = (positions[b, j] - positions[b, i]).norm() <= 1.5
                sent = td["agents", "message"][b, j].clamp(-1, 1)
                assert torch.equal(slot[-2:], sent if heard else torch.zeros(2))


@pytest.mark.parametrize("model", ["paper", "levels", "energy"])
def test_a_uav_knows_whether_its_move_was_cancelled(model):
    """``("agents", "cancelled")`` is true exactly for a UAV that asked for a move to a position on the grid (and not
    inside a building, nor out of service) and kept its position, by a loop over positions written here; false after
    a reset; absent under central observations."""
    kw = {k: v for k, v in MODELS[model].items() if k != "preset"}
    env = UAVSpectrumEnv(batch_size=64, preset=MODELS[model]["preset"], observation="local", seed=3, **kw)
    check_env_specs(env)
    gen = torch.Generator().manual_seed(4)
    levels = env.cfg.num_levels > 1
    moves = [(0, -1, 0), (0, 1, 0), (-1, 0, 0), (1, 0, 0)] + ([(0, 0, 1), (0, 0, -1)] if levels else [])
    move_actions = [0, 1, 2, 3] + ([6, 7] if levels else [])
    td = env.reset()
    assert not td["agents", "cancelled"].any()
    cancelled = 0
    for _ in range(6):
        allowed = td["agents", "action_mask"].float().flatten(0, 1)  # and moves off the grid, which are no asks
        allowed[:, :4] = 1.0
        action = torch.multinomial(allowed, 1, generator=gen).view(64, env.num_uavs)
        td["agents", "action"] = action
        out = env.step(td)["next"]
        before, after = (
            [
                (*t["positions"][b, i].tolist(), int(t["levels"][b, i]) if levels else 0)
                for b in range(64)
                for i in range(env.num_uavs)
            ]
            for t in (td, out)
        )
        for k, (a, p, q) in enumerate(zip(action.flatten().tolist(), before, after, strict=True)):
            b, i = divmod(k, env.num_uavs)
            asked = a in move_actions and bool(td["agents", "action_mask"][b, i, a])
            if asked:
                dx, dy, dz = moves[move_actions.index(a)]
                asked = (p[0] + dx, p[1] + dy, p[2] + dz) != p
            expected = asked and p == q
            assert bool(out["agents", "cancelled"][b, i]) == expected, (b, i, a, p, q)
            cancelled += expected
        td = out
    assert cancelled > 10
    assert "cancelled" not in UAVSpectrumEnv(batch_size=2, grid=(4, 4), num_uavs=2).reset()["agents"].keys()


@pytest.mark.parametrize(
    "bad, message",
    [
        (torch.full((2, 3, 2), float("nan")), "holds NaN or infinity"),
        (torch.zeros(2, 3, 5), "expected [2, 3, 2] floats"),
        (torch.zeros(2, 3, 2, dtype=torch.long), "dtype torch.int64"),
    ],
)
def test_a_bad_message_is_refused_in_one_line(bad, message):
    env = UAVSpectrumEnv(batch_size=2, grid=(6, 6), num_uavs=3, observation="local", message_size=2)
    td = env.reset()
    td["agents", "action"] = torch.zeros(2, 3, dtype=torch.long)
    td.set(("agents", "message"), bad)
    with pytest.raises(InvalidOption, match=message.replace("[", r"\[").replace("]", r"\]")):
        env.step(td)


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(observation="nearby"), "observation='nearby' is invalid: allowed values are 'central', 'local'"),
        (dict(comm_radius=2), "comm_radius=2 is invalid: only observation='local' reads it"),
        (dict(observation="local", comm_radius=-1), "give a finite distance >= 0 in cells"),
        (dict(observation="local", comm_radius=float("inf")), "give a finite distance >= 0 in cells"),
        (dict(observation="local", message_size=65), "message_size=65 is invalid: give a whole number"),
        (dict(observation="local", message_size=1.5), "message_size=1.5 is invalid"),
        (dict(message_size=4), "message_size=4 is invalid: only observation='local' reads it"),
    ],
)
def test_bad_observation_settings_are_refused_in_one_line(kw, message):
    with pytest.raises(InvalidOption, match=message.replace("(", r"\(").replace(")", r"\)")):
        make_config("paper", **kw)


def test_a_physical_channel_reads_the_radius_in_metres():
    cfg = make_config("a2g_urban", observation="local", comm_radius=100.0)
    assert cfg.comm_radius_cells == 100.0 / cfg.cell_size
    with pytest.raises(InvalidOption, match="in m, or None"):
        make_config("a2g_urban", observation="local", comm_radius=-5.0)
