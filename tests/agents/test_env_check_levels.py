"""A policy acts only in environments of its run's altitude levels and city (agents/env_check.py): a refusal in one
line names what differs; a walk at levels in its own city passes every tensordict check."""

import pytest

from uavrl.agents.env_check import RunEnvironment
from uavrl.envs import UAVSpectrumEnv, make_config

RUN = make_config(
    "a2g_urban", grid=(3, 3), num_uavs=2, altitudes_m=[20, 100, 300], city="highrise", environment="highrise"
)


def test_a_walk_at_levels_in_its_city_passes_every_check():
    """Buildings block moves at low levels (the observation marks them -1 like the grid's edges): no refusal."""
    run, env = RunEnvironment(RUN), UAVSpectrumEnv(batch_size=32, config=RUN, seed=2)
    run.check_env(env)
    run._checked_shape = None  # check every tensordict in full
    td = env.reset()
    for _ in range(12):
        run.check(td)
        run._checked_shape = None
        td = env.step_mdp(env.rand_step(td))


@pytest.mark.parametrize(
    "other, differs",
    [
        (RUN.replace(altitudes_m=None, city="none", environment="urban"), "the environment has one altitude, no city"),
        (RUN.replace(altitudes_m=(20.0, 100.0)), "the environment has altitudes_m=[20, 100], city 'highrise'"),
        (RUN.replace(city_seed=1), "city 'highrise' (city_seed=1, los=geometric)"),
    ],
    ids=["flat", "other-levels", "other-city"],
)
def test_an_environment_of_other_levels_or_another_city_is_refused(other, differs):
    with pytest.raises(ValueError) as refusal:
        RunEnvironment(RUN).check_env(UAVSpectrumEnv(batch_size=2, config=other))
    line = str(refusal.value)
    assert "\n" not in line and differs in line, line
    assert "altitudes_m=[20, 100, 300], city 'highrise' (city_seed=0, los=geometric))" in line


def test_a_flat_run_refuses_an_environment_at_levels():
    flat = RunEnvironment(make_config("a2g_urban", grid=(3, 3), num_uavs=2))
    with pytest.raises(ValueError, match=r"the environment has altitudes_m=\[20, 100, 300\], city 'highrise'"):
        flat.check_env(UAVSpectrumEnv(batch_size=2, config=RUN))
    # a tensordict of the levels' environment: its observations are longer than the run's
    with pytest.raises(ValueError, match="its observations have 22 features, not 16"):
        flat.check(UAVSpectrumEnv(batch_size=2, config=RUN.replace(city="none", environment="urban")).reset())
