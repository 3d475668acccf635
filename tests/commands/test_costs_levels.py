"""What a run at altitude levels costs, before the work (uavrl/costs.py, envs/limits.py): the Q tables and the World's
tables grow with the positions (every cell at every level), and a refusal names env.altitudes_m where it was typed."""

import pytest

from uavrl.envs import make_config
from uavrl.envs.limits import table_bytes, world_bytes

LEVELS = "env.altitudes_m=[" + ",".join(str(metres) for metres in range(20, 84)) + "]"  # 64 levels


def refusal(*overrides: str) -> str | None:
    from uavrl.cli import compose_config
    from uavrl.train import check_settings

    try:
        check_settings(compose_config("config", list(overrides)), list(overrides))
    except ValueError as err:
        return str(err)
    return None


def test_the_tables_grow_with_the_positions():
    flat = make_config("a2g_urban", grid=(3, 3), num_uavs=2)
    levels = flat.replace(altitudes_m=(30.0, 100.0, 300.0))
    assert levels.num_positions == 27 and levels.num_joint_actions == 64
    # Q table (27^2 states x 8^2 joint actions) plus the model tables over 27^2 placements
    per_action, per_configuration = 4 + 1 + 1 + 1, 8 + 8 + 4
    expected = 27**2 * 64 * 8 + 27**2 * 64 * per_action + 27**2 * 4 * per_configuration
    assert (
        table_bytes(levels, 1) == expected
        and table_bytes(flat, 1) == 9**2 * 36 * (8 + per_action) + 9**2 * 4 * per_configuration
    )
    assert world_bytes(levels, 1) > world_bytes(flat, 1)


def test_a_q_table_too_large_at_levels_names_the_levels_typed():
    line = refusal(
        "agent=tabular", "env=a2g_urban", LEVELS, "env.grid=[2,2]", "env.num_uavs=2", "agent.memory_budget=1e8"
    )
    assert line is not None and "\n" not in line, line
    assert (
        line.startswith("env.altitudes_m=[20,21,22,")
        and " is invalid: the team Q tables on 2x2 at 64 altitude " in line
    )
    assert "the levels of env.altitudes_m 64" in line and "lower env.grid or env.num_uavs or env.altitudes_m" in line


def test_a_small_tabular_run_at_levels_is_within_its_budgets():
    assert (
        refusal("agent=tabular", "env=a2g_urban", "env.altitudes_m=[30,100,300]", "env.grid=[3,3]", "env.num_uavs=2")
        is None
    )


def test_the_learner_refuses_a_table_at_levels_before_building_it():
    from uavrl.agents.tabular import TeamQLearner

    cfg = make_config("a2g_urban", grid=(4, 4), num_uavs=3, altitudes_m=[30, 60, 100, 300])
    with pytest.raises(ValueError, match=r"^the team Q table of 3 UAVs on 4x4 at 4 altitude levels would need [\d,]+ "):
        TeamQLearner(cfg, memory_budget=2**30)
