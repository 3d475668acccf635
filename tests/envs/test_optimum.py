"""The exact optimum U* (docs/model.md) and the joint-action tables against plain-Python searches."""

from __future__ import annotations

import itertools

import pytest
import torch

from uavrl.envs import UAVSpectrumEnv, decode_joint_actions, joint_targets

MOVES = {0: (0, -1), 1: (0, 1), 2: (-1, 0), 3: (1, 0)}

CASES = [
    ((2, 2), 1, "paper", {}),
    ((2, 2), 2, "paper", {"layout": "random"}),
    ((2, 2), 4, "paper", {}),
    ((3, 2), 3, "paper", {"layout": "random", "direct_links": True}),
    ((1, 5), 2, "paper", {"layout": "random"}),
    ((3, 3), 2, "paper", {"lease_rule": False, "layout": "random"}),
    ((3, 3), 4, "paper", {"layout": "random"}),
    ((4, 3), 3, "paper", {"layout": "random", "p_pt": 0.001}),
    ((4, 4), 2, "paper", {"direct_links": True}),
    ((5, 2), 5, "paper", {"layout": "random"}),
    ((2, 2), 2, "reference_code", {}),
    ((3, 3), 3, "reference_code", {}),
    ((4, 3), 4, "reference_code", {}),
    ((4, 4), 3, "paper", {"layout": "random", "alpha": 3.0, "beta1": 2.0}),
]


def brute_force(env):
    """Plain enumeration with ``env.utility`` (checked against hand-worked rates in test_env): every set of cells,
    every task vector."""
    L1, L2 = env.cfg.grid
    N = env.num_uavs
    cells = list(itertools.product(range(L1), range(L2)))
    configs = [(c, t) for c in itertools.combinations(cells, N) for t in itertools.product((0, 1), repeat=N)]
    pos = torch.tensor([c for c, _ in configs]).unsqueeze(0).expand(env.num_worlds, -1, -1, -1)
    tasks = torch.tensor([t for _, t in configs]).unsqueeze(0).expand(env.num_worlds, -1, -1)
    return env.utility(pos, tasks)[2].amax(-1)


@pytest.mark.parametrize("grid,N,preset,options", CASES)
def test_exchange_equals_brute_force(grid, N, preset, options):
    B = 6
    env = UAVSpectrumEnv(batch_size=B, grid=grid, num_uavs=N, preset=preset, seed=sum(grid) * 7 + N, **options)
    env.reset()
    u_ex, pos_ex, tasks_ex = env.optimum(method="exchange")
    u_bf, pos_bf, tasks_bf = env.optimum(method="brute")
    torch.testing.assert_close(u_ex, u_bf, rtol=1e-12, atol=0)
    torch.testing.assert_close(u_ex, brute_force(env), rtol=1e-12, atol=0)
    for u, pos, tasks in ((u_ex, pos_ex, tasks_ex), (u_bf, pos_bf, tasks_bf)):
        # the returned configurations are valid and reach U*
        cells = pos[..., 1] * grid[0] + pos[..., 0]
        assert (cells.sort(-1).values.diff(dim=-1) > 0).all() and (pos >= 0).all()
        assert (pos[..., 0] < grid[0]).all() and (pos[..., 1] < grid[1]).all()
        torch.testing.assert_close(env.utility(pos, tasks)[2], u, rtol=1e-12, atol=0)


def test_auto_picks_an_exact_method():
    env = UAVSpectrumEnv(batch_size=3, grid=(4, 4), num_uavs=3, layout="random", seed=1)
    env.reset()
    torch.testing.assert_close(env.optimum()[0], env.optimum(method="brute")[0], rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="method='fast'"):
        env.optimum(method="fast")


def test_random_layout_needs_a_reset_first():
    env = UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2, layout="random")
    with pytest.raises(RuntimeError, match="reset"):
        env.optimum()


def test_ten_uavs_on_twenty_by_twenty():
    """N = 10 on 20x20 (400^10 placements): the exchange method runs and beats every sampled configuration."""
    B = 4
    env = UAVSpectrumEnv(batch_size=B, grid=(20, 20), num_uavs=10, layout="random", seed=3)
    env.reset()
    u, pos, tasks = env.optimum()
    torch.testing.assert_close(env.utility(pos, tasks)[2], u, rtol=1e-12, atol=0)
    assert all(len(set((pos[w, :, 1] * 20 + pos[w, :, 0]).tolist())) == 10 for w in range(B))
    gen = torch.Generator().manual_seed(0)
    samples = 2000
    cells = torch.rand(B, samples, 400, generator=gen).argsort(-1)[..., :10]
    rand_tasks = torch.randint(0, 2, (B, samples, 10), generator=gen)
    sampled = env.utility(torch.stack([cells % 20, cells // 20], -1), rand_tasks)[2]
    assert (sampled <= u.unsqueeze(-1) + 1e-12).all()
    # local moves from the optimum never improve it: single-UAV relocations to any free cell, single task flips
    for w in range(B):
        base = pos[w].clone()
        occupied = set((base[:, 1] * 20 + base[:, 0]).tolist())
        free = torch.tensor([c for c in range(400) if c not in occupied])
        for i in range(10):
            moved = base.unsqueeze(0).repeat(len(free), 1, 1)
            moved[:, i] = torch.stack([free % 20, free // 20], -1)
            cand = env.utility(moved.unsqueeze(0).expand(B, -1, -1, -1), tasks[w].expand(B, len(free), -1))[2][w]
            assert (cand <= u[w] + 1e-12).all()
            flipped = tasks[w].clone()
            flipped[i] = 1 - flipped[i]
            assert env.utility(base.expand(B, -1, -1), flipped.expand(B, -1))[2][w] <= u[w] + 1e-12


def python_valid(cells_xy, joint, L1, L2):
    targets = []
    for (x, y), a in zip(cells_xy, joint, strict=True):
        cell = (x + MOVES[a][0], y + MOVES[a][1]) if a < 4 else (x, y)
        if not (0 <= cell[0] < L1 and 0 <= cell[1] < L2):
            return False
        targets.append(cell)
    return len(set(targets)) == len(targets)


@pytest.mark.parametrize(
    "grid,N", [((1, 1), 1), ((1, 3), 2), ((3, 3), 1), ((3, 3), 2), ((2, 2), 3), ((4, 3), 3), ((2, 2), 4)]
)
def test_joint_action_mask_matches_python(grid, N):
    L1, L2 = grid
    B = 8
    env = UAVSpectrumEnv(batch_size=B, grid=grid, num_uavs=N, seed=N)
    td = env.reset()
    mask = env.joint_action_mask()
    assert mask.shape == (B, 6**N)
    decoded = decode_joint_actions(N)
    for w in range(B):
        cells_xy = [tuple(p) for p in td["positions"][w].tolist()]
        want = [python_valid(cells_xy, [(j // 6**i) % 6 for i in range(N)], L1, L2) for j in range(6**N)]
        assert mask[w].tolist() == want
        assert decoded[7 % 6**N].tolist() == [(7 % 6**N // 6**i) % 6 for i in range(N)]
    # explicit positions give the same as the current ones; the per-UAV mask is the marginal for N = 1
    assert env.joint_action_mask(td["positions"]).equal(mask)
    if N == 1:
        assert mask.equal(td["agents", "action_mask"][:, 0])
    targets = joint_targets(td["positions"][..., 1] * L1 + td["positions"][..., 0], env.neighbours, N)
    assert targets.shape == (B, 6**N, N)
    assert ((targets >= 0).all(-1) | ~mask).all() and ((targets < 0).any(-1) <= ~mask).all()


def test_joint_tables_refuse_huge_n():
    with pytest.raises(ValueError, match="num_uavs=8"):
        decode_joint_actions(8)
