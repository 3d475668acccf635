"""BenchMARL's algorithms on the UAV task (needs the extra: pip install torch==2.13.0 -e ".[benchmarl]")."""

import json
import subprocess
import sys

import pytest
import yaml

pytest.importorskip("benchmarl")

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type  # noqa: E402

from uavrl.agents.benchmarl import YardstickCallback  # noqa: E402
from uavrl.agents.evaluation import evaluate  # noqa: E402
from uavrl.benchmarl import check_settings, train  # noqa: E402
from uavrl.cli import compose_config  # noqa: E402
from uavrl.experiment.benchmarl import load_experiment  # noqa: E402

# a few thousand frames: two batches of 1,200 (40 worlds x 30 steps), evaluated after each
TINY = [
    "task=uavrl/tiny_4x4",
    "experiment.max_n_frames=2400",
    "experiment.on_policy_collected_frames_per_batch=1200",
    "experiment.off_policy_collected_frames_per_batch=1200",
    "experiment.on_policy_n_envs_per_worker=40",
    "experiment.off_policy_n_envs_per_worker=40",
    "experiment.evaluation_interval=1200",
    "experiment.evaluation_episodes=4",
    "experiment.on_policy_n_minibatch_iters=2",
    "experiment.on_policy_minibatch_size=200",
    "experiment.off_policy_n_optimizer_steps=4",
    "experiment.off_policy_train_batch_size=64",
    "model.num_cells=[32]",
    "critic_model.num_cells=[32]",
    "eval.num_starts=8",
]
# what a report reads from a run of python -m uavrl.train, and BenchMARL's runs write too
REPORTED = {"agent", "env", "env_steps", "iterations", "train_seconds", "total_seconds", "eval/optimality"}


@pytest.fixture
def masked_choices(monkeypatch):
    """Every collected action, and whether the action mask allowed it."""
    allowed = []

    def on_batch_collected(self, batch):
        mask, action = batch["agents", "action_mask"], batch["agents", "action"]
        allowed.append(mask.gather(-1, action.unsqueeze(-1)).all().item())
        assert "utility" not in batch["next"].keys()  # the task's env carries no diagnostics

    monkeypatch.setattr(YardstickCallback, "on_batch_collected", on_batch_collected, raising=False)
    return allowed


@pytest.mark.parametrize("algorithm", ["qmix", "iql", "mappo"])
def test_short_run_completes_masked_and_reported(tmp_path, algorithm, masked_choices):
    run_dir = train(compose_config("benchmarl", [f"algorithm={algorithm}", *TINY, f"run_dir={tmp_path / 'run'}"]))
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert REPORTED <= metrics.keys() and metrics["agent"] == f"benchmarl_{algorithm}"
    assert metrics["env_steps"] == 2400 and metrics["task"] == "uavrl/tiny_4x4"
    assert 0 < metrics["eval/optimality"] <= 1 and "eval/return_ratio" in metrics  # exact on 4x4
    curve = json.loads((run_dir / "curve.json").read_text())
    assert [point["frames"] for point in curve] == [1200, 2400] and curve[-1]["time/train_cpu_seconds"] > 0
    assert masked_choices == [True, True]
    tags = set(EventAccumulator(str(run_dir)).Reload().Tags()["scalars"])
    assert {"eval/return_ratio", "eval/optimality", "eval/reach_999"} <= tags
    assert any(path.name.startswith(f"{algorithm}_tiny_4x4") for path in run_dir.iterdir())  # BenchMARL's folder


def test_a_short_run_in_a_city_with_altitude_levels(tmp_path, masked_choices):
    """The same task in an urban city with three altitude levels: BenchMARL's MAPPO picks among the 8 actions its
    mask allows (none into a building or off the levels) and the yardstick is exact."""
    city = ["env.preset=a2g_urban", "env.channel=al_hourani", "env.cell_size=50", "env.altitude_m=100"]
    city += ["env.city=urban", "env.environment=urban", "env.altitudes_m=[30,100,300]"]
    run_dir = train(compose_config("benchmarl", ["algorithm=mappo", *TINY, *city, f"run_dir={tmp_path / 'run'}"]))
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["env_steps"] == 2400 and 0 < metrics["eval/optimality"] <= 1 and "eval/return_ratio" in metrics
    assert masked_choices == [True, True]
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())["env"]
    assert saved["altitudes_m"] == [30, 100, 300] and saved["city"] == "urban"


@pytest.mark.parametrize("algorithm", ["ippo", "mappo"])
def test_a_short_run_on_local_observations_acts_on_what_each_uav_hears(tmp_path, algorithm, masked_choices):
    """IPPO and MAPPO on local observations (radius 1 cell): the run completes, and the trained policy's action for
    UAV 0 is the same when every UAV beyond its range moves elsewhere beyond it and switches task (the deterministic
    policy, as evaluated)."""
    import torch
    from tensordict import TensorDict

    from tests.envs.test_local import perturbed_out_of_range
    from uavrl.envs import World

    local = ["env.observation=local", "env.comm_radius=1.0"]
    run_dir = train(compose_config("benchmarl", [f"algorithm={algorithm}", *TINY, *local, f"run_dir={tmp_path / 'r'}"]))
    assert masked_choices == [True, True]
    experiment = load_experiment(run_dir)
    cfg = experiment.task.model_config
    assert cfg.local and cfg.comm_radius == 1.0
    world, gen = World(cfg, batch_size=1), torch.Generator().manual_seed(0)
    N, (L1, L2) = cfg.num_uavs, cfg.grid
    acted = []
    for _ in range(100):
        code = 2 * torch.randperm(L1 * L2, generator=gen)[:N] + torch.randint(0, 2, (N,), generator=gen)
        moved, _ = perturbed_out_of_range(code, torch.zeros(N, 0), (L1, L2), 1.0, gen)
        for c in (code, moved):
            out = world.configurations(c[None])
            group = TensorDict({"observation": out["observation"], "action_mask": out["action_mask"]}, [1, N])
            with set_exploration_type(ExplorationType.DETERMINISTIC):
                acted.append(experiment.policy(TensorDict({"agents": group}, [1]))["agents", "action"][0, 0])
    assert all(torch.equal(a, b) for a, b in zip(acted[::2], acted[1::2], strict=True))


def test_a_finished_run_reloads_to_act_as_it_was_evaluated_writing_nothing(tmp_path):
    run_dir = train(compose_config("benchmarl", ["algorithm=iql", *TINY, f"run_dir={tmp_path / 'run'}"]))
    before = {path: path.stat().st_mtime_ns for path in run_dir.rglob("*")}
    experiment = load_experiment(run_dir)
    assert {path: path.stat().st_mtime_ns for path in run_dir.rglob("*")} == before
    assert experiment.total_frames == 2400
    saved = json.loads((run_dir / "metrics.json").read_text())
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        again = evaluate(experiment.policy, experiment.task.model_config, num_starts=8)
    assert again["eval/return_ratio"] == saved["eval/return_ratio"]  # the final weights, not a fresh network


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda d: d, "is no finished run of python -m uavrl.benchmarl: its metrics.json and config.yaml"),
        (lambda d: (d / "metrics.json").write_text("[1, 2]") and d, "cannot be read as the command writes them"),
        (lambda d: (d / "file").touch() or d / "file", "is a file, not a directory"),
    ],
)
def test_a_directory_that_is_no_run_is_refused_in_one_line(tmp_path, make, words):
    with pytest.raises((ValueError, OSError), match=words):
        load_experiment(make(tmp_path))


def test_same_seed_same_result(tmp_path):
    runs = [
        json.loads(
            (
                train(compose_config("benchmarl", ["algorithm=iql", *TINY, f"run_dir={tmp_path / d}"])) / "metrics.json"
            ).read_text()
        )
        for d in ("a", "b")
    ]
    same = [{k: v for k, v in r.items() if k.startswith("eval/")} for r in runs]
    assert same[0] == same[1]


@pytest.mark.parametrize(
    "override, message",
    [
        ("algorithm=maddpg", "algorithm=maddpg is invalid: it acts in continuous action spaces only"),
        ("env.num_uavs=0", "num_uavs=0"),
        ("eval.num_starts=0", "eval.num_starts=0 is invalid"),
        ("eval.horizon=100000000000", "eval.horizon=100000000000 is invalid: the evaluation .* over memory_budget="),
        ("experiment.off_policy_n_envs_per_worker=100000000", "experiment.off_policy_n_envs_per_worker=100000000 is"),
        ("env.message_size=2", "env.message_size=2 is invalid for python -m uavrl.benchmarl: BenchMARL's policies"),
    ],
)
def test_bad_settings_are_refused_in_one_line(override, message):
    overrides = ["algorithm=iql", override] if not override.startswith("algorithm") else [override]
    overrides = ["env.observation=local", *overrides] if override.startswith("env.message") else overrides
    with pytest.raises(ValueError, match=message):
        check_settings(compose_config("benchmarl", overrides), overrides)


@pytest.mark.parametrize(
    "argument, message",
    [
        ("algorithm=masac_typo", "error: In 'benchmarl': Could not find 'algorithm/masac_typo'"),
        ("algorithm=iddpg", "error: algorithm=iddpg is invalid: it acts in continuous action spaces only"),
        (
            "task=vmas/balance",
            "error: task=vmas/balance is invalid: allowed tasks are uavrl/city_urban_10x10, uavrl/n6_10x10, "
            "uavrl/paper",
        ),
    ],
)
def test_command_refuses_in_one_line(tmp_path, argument, message):
    done = subprocess.run(
        [sys.executable, "-m", "uavrl.benchmarl", argument], capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    assert done.returncode == 1 and done.stderr.strip().startswith(message), done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "runs").exists()


def test_task_specs_are_those_benchmarl_reads():
    from uavrl.agents.benchmarl import UAVTask
    from uavrl.envs import make_config

    cfg = make_config("paper", grid=(4, 4), num_uavs=3)
    task = UAVTask.from_model_config("t", cfg)
    assert task.model_config == cfg
    env = task.get_env_fun(num_envs=5, continuous_actions=False, seed=0, device="cpu")()
    td = env.reset()
    assert task.group_map(env) == {"agents": ["uav_0", "uav_1", "uav_2"]}
    assert task.observation_spec(env)["agents", "observation"].is_in(td["agents", "observation"][0])
    assert task.action_mask_spec(env)["agents", "action_mask"].is_in(td["agents", "action_mask"][0])
    assert task.state_spec(env)["state"].is_in(td["state"][0])
    assert task.action_spec(env)["agents", "action"].shape == (3,)
