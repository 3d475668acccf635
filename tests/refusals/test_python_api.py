"""The Python API refuses bad arguments in one line of uavrl's own errors, naming the argument.

``InvalidOption`` (a ``ValueError``) for a wrong value, ``InvalidType`` (also a ``TypeError``) for a wrong type:
``load_policy``, ``UAVSpectrumEnv`` (construction, ``reset``, ``step``, ``to``), the Gymnasium and PettingZoo adapters
and ``uavrl.agents.evaluation.evaluate``.  What a part does not read is refused the same way by every part; a
``seed`` given
to ``UAVSpectrumEnv.reset`` seeds as ``set_seed`` does.
"""

from __future__ import annotations

import importlib.util

import pytest
import torch
from tensordict import TensorDict

from uavrl import load_policy
from uavrl.agents.evaluation import evaluate
from uavrl.envs import InvalidOption, InvalidType, UAVSpectrumEnv, make_config
from uavrl.train import train

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

CFG = make_config("paper", grid=(3, 3), num_uavs=2)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A saved run of the random baseline on 3x3 (no training: a second to make)."""
    from uavrl.cli import compose_config

    where = tmp_path_factory.mktemp("api") / "run"
    overrides = ["agent=random", "env.grid=[3,3]", "eval.num_starts=2", "progress=false", f"run_dir={where}"]
    return train(compose_config("config", overrides))


def refused(call, kind, argument: str, text: str):
    with pytest.raises(kind) as err:
        call()
    assert isinstance(err.value, InvalidOption) and err.value.option == argument, (type(err.value), err.value)
    message = str(err.value)
    assert "\n" not in message and text in message, message


LOAD_POLICY = [
    (lambda run: load_policy(run, env_config={"grid": (3, 3)}), InvalidType, "env_config", "give a ModelConfig"),
    (lambda run: load_policy(run, env_config="paper"), InvalidType, "env_config", "env_config='paper' is invalid"),
    (lambda run: load_policy(None), InvalidType, "run_dir", "run_dir=None is invalid"),
    (lambda run: load_policy(0), InvalidType, "run_dir", "run_dir=0 is invalid"),
    (lambda run: load_policy(run, run="0"), InvalidType, "run", "run='0' is invalid"),
    (lambda run: load_policy(run, run=True), InvalidType, "run", "run=True is invalid"),
    (lambda run: load_policy(run, run=5), InvalidOption, "run", "run=5 is invalid: this run directory holds 1"),
    (lambda run: load_policy(run, device="gpu"), InvalidOption, "device", "device='gpu' is invalid"),
    (lambda run: load_policy(run, device="meta"), InvalidOption, "device", "device='meta' is invalid"),
    (lambda run: load_policy(run, device=3.5), InvalidOption, "device", "device=3.5 is invalid"),
]


@pytest.mark.parametrize(("call", "kind", "argument", "text"), LOAD_POLICY)
def test_load_policy_refuses_bad_arguments(run_dir, call, kind, argument, text):
    refused(lambda: call(run_dir), kind, argument, text)


def test_load_policy_names_a_missing_run():
    with pytest.raises(FileNotFoundError, match=r"^run_dir=0 does not exist \(give a run directory"):
        load_policy("0")


def env(**options):
    return UAVSpectrumEnv(batch_size=2, grid=(3, 3), num_uavs=2, **options)


def with_action(action, device=None) -> TensorDict:
    """A tensordict holding only ``("agents", "action")``, as a hand-written step input."""
    return TensorDict({"agents": TensorDict({"action": action}, batch_size=[2], device=device)}, [2], device=device)


LONG = dict(dtype=torch.long)
ENV = [
    (lambda: env(foo=1), InvalidOption, "foo", "unknown model option 'foo'"),
    (lambda: UAVSpectrumEnv(config={"grid": (3, 3)}), InvalidType, "config", "give a ModelConfig"),
    (lambda: UAVSpectrumEnv(config=CFG, layout="random"), InvalidOption, "layout", "give either config= or model"),
    (lambda: env(diagnostics="yes"), InvalidType, "diagnostics", "diagnostics='yes' is invalid"),
    (lambda: env(agent_rewards=1), InvalidType, "agent_rewards", "agent_rewards=1 is invalid"),
    (lambda: env(seed=-1), InvalidOption, "seed", "seed=-1 is invalid"),
    (lambda: env(seed="1"), InvalidType, "seed", "seed='1' is invalid"),
    (lambda: env().to("meta"), InvalidOption, "device", "device='meta' is invalid"),
    (lambda: env().to("cuda:99"), InvalidOption, "device", "device='cuda:99'"),
    (lambda: env().reset(foo=1), InvalidOption, "foo", "reset() got foo=1: UAVSpectrumEnv.reset reads"),
    (lambda: env().reset(options={"a": 1}), InvalidOption, "options", "reset() got options={'a': 1}"),
    (lambda: env().reset({"_reset": True}), InvalidType, "tensordict", "reset() got a dict"),
    (lambda: env().reset(seed=2.5), InvalidType, "seed", "seed=2.5 is invalid"),
    (lambda: env().reset(seed=2**63), InvalidOption, "seed", "is invalid: give a whole number in [0, 2^63)"),
    (lambda: env().reset(TensorDict(_reset=torch.ones(2, 3, dtype=torch.bool), batch_size=[2])), InvalidOption,
     "_reset", "'_reset' has shape (2, 3)"),
    (lambda: stepped(env(), {"agents": 1}), InvalidType, "tensordict", "step() got a dict"),
    (lambda: stepped(env(), with_action(torch.zeros(2, 3, **LONG))), InvalidOption, "('agents', 'action')",
     "('agents', 'action') has shape (2, 3): expected (2, 2)"),
    (lambda: stepped(env(), with_action(torch.zeros(2, 2, dtype=torch.long, device="meta"))), InvalidOption,
     "('agents', 'action')", "is on device meta: expected the CPU or a CUDA device"),
    (lambda: stepped(env(), with_action(torch.zeros(2, 2, dtype=torch.long, device="meta"), "meta")),
     InvalidOption, "('agents', 'action')", "is on device meta"),
    (lambda: stepped(env(), with_action(torch.zeros(2, 2))), InvalidType, "('agents', 'action')",
     "has dtype torch.float32"),
    (lambda: stepped(env(), with_action(torch.ones(2, 2, dtype=torch.bool))), InvalidType, "('agents', 'action')",
     "has dtype torch.bool"),
    (lambda: stepped(env(), with_action(torch.full((2, 2), 6))), InvalidOption, "('agents', 'action')",
     "holds 6: actions are 0..5"),
    (lambda: stepped(env(), with_action(torch.full((2, 2), -1))), InvalidOption, "('agents', 'action')", "holds -1"),
    (lambda: stepped(env(), TensorDict({}, [2])), InvalidOption, "('agents', 'action')", "step() got no"),
    (lambda: stepped(env(), env().reset().expand(2, 2).clone()), InvalidOption, "tensordict", "of batch size [2, 2]"),
]  # fmt: skip


def stepped(environment, tensordict):
    environment.reset()
    return environment.step(tensordict)


@pytest.mark.parametrize(("call", "kind", "argument", "text"), ENV, ids=[case[3][:40] for case in ENV])
def test_the_environment_refuses_bad_arguments(call, kind, argument, text):
    refused(call, kind, argument, text)


def test_reset_with_a_seed_seeds_as_set_seed():
    """TorchRL seeds with ``set_seed``; ``reset(seed=s)`` is that then ``reset()`` (as Gymnasium's reset seeds)."""
    a, b = env(), env()
    b.set_seed(11)
    first = a.reset(seed=11)
    assert torch.equal(first["positions"], b.reset()["positions"])
    assert torch.equal(a.reset(seed=11)["positions"], first["positions"])  # the same seed: the same start
    starts = {tuple(a.reset(seed=s)["positions"].flatten().tolist()) for s in range(6)}
    assert len(starts) > 1  # and another seed another start


def policy_of(run_dir):
    return load_policy(run_dir)[0]


EVALUATE = [
    (lambda p: evaluate(None, CFG), InvalidType, "policy", "policy=None is invalid"),
    (lambda p: evaluate(p, {"grid": (3, 3)}), InvalidType, "cfg", "give a ModelConfig"),
    (lambda p: evaluate(p, CFG, num_starts=0), InvalidOption, "num_starts", "num_starts=0 is invalid"),
    (lambda p: evaluate(p, CFG, num_starts="4"), InvalidType, "num_starts", "num_starts='4' is invalid"),
    (lambda p: evaluate(p, CFG, num_starts=True), InvalidType, "num_starts", "num_starts=True is invalid"),
    (lambda p: evaluate(p, CFG, horizon=2.5), InvalidOption, "horizon", "horizon=2.5 is invalid"),
    (lambda p: evaluate(p, CFG, gamma=2), InvalidOption, "gamma", "gamma=2 is invalid"),
    (lambda p: evaluate(p, CFG, seed=-1), InvalidOption, "seed", "seed=-1 is invalid"),
    (lambda p: evaluate(p, CFG, device="meta"), InvalidOption, "device", "device='meta' is invalid"),
]


@pytest.mark.parametrize(("call", "kind", "argument", "text"), EVALUATE, ids=[case[3] for case in EVALUATE])
def test_evaluate_refuses_bad_arguments(run_dir, call, kind, argument, text):
    refused(lambda: call(policy_of(run_dir)), kind, argument, text)


needs_gym = pytest.mark.skipif(
    importlib.util.find_spec("gymnasium") is None or importlib.util.find_spec("pettingzoo") is None,
    reason='the adapters: pip install -e ".[gym]"',
)


def adapters():
    from uavrl.envs.adapters.gym_env import UAVSpectrumGymEnv, UAVSpectrumVectorEnv
    from uavrl.envs.adapters.pettingzoo_env import UAVSpectrumParallelEnv

    return {
        "gym": lambda **kw: UAVSpectrumGymEnv(grid=(3, 3), **kw),
        "vector": lambda **kw: UAVSpectrumVectorEnv(2, grid=(3, 3), **kw),
        "pettingzoo": lambda **kw: UAVSpectrumParallelEnv(grid=(3, 3), **kw),
    }


@pytest.mark.gym
@needs_gym
@pytest.mark.parametrize("adapter", ["gym", "vector", "pettingzoo"])
def test_every_adapter_refuses_what_it_does_not_read_the_same_way(adapter):
    """Model options no part reads, a config that is none, a foreign render mode, a bad seed: the same refusal from
    every adapter; reset options from the Gymnasium adapters and the TorchRL environment."""
    make = adapters()[adapter]
    if adapter != "pettingzoo":  # PettingZoo's parallel_api_test resets with options={"options": 1}: accepted
        refused(lambda: make().reset(options={"a": 1}), InvalidOption, "options", "takes no reset options")
        refused(lambda: make().reset(options="a"), InvalidType, "options", "options='a' is invalid")
    refused(lambda: make(foo=1), InvalidOption, "foo", "unknown model option 'foo'")
    refused(lambda: make(config={"grid": (3, 3)}), InvalidType, "config", "give a ModelConfig")
    refused(lambda: make(render_mode="human"), InvalidOption, "render_mode", "render_mode='human' is invalid")
    refused(lambda: make().reset(seed=-1), InvalidOption, "seed", "seed=-1 is invalid")
    make().reset(options={})  # empty options: nothing to refuse


@pytest.mark.gym
@needs_gym
def test_the_adapters_refuse_bad_actions_in_one_line():
    make = adapters()
    gym, vector, parallel = make["gym"](), make["vector"](), make["pettingzoo"]()
    for environment in (gym, vector, parallel):
        environment.reset(seed=0)
    refused(lambda: gym.step([0, 0, 0]), InvalidOption, "action", "action has shape (3,): expected (2,)")
    refused(lambda: gym.step([0.5, 1.0]), InvalidType, "action", "has dtype float64")
    refused(lambda: gym.step([[0], [0, 1]]), InvalidType, "action", "action is no array of integers")
    refused(lambda: gym.step(torch.zeros(2, dtype=torch.long, device="meta")), InvalidOption, "action", "device meta")
    refused(lambda: gym.step([0, 9]), InvalidOption, "action", "action holds 9")
    refused(lambda: vector.step([[0, 0]]), InvalidOption, "actions", "actions has shape (1, 2): expected (2, 2)")
    refused(lambda: vector.reset(seed="1"), InvalidType, "seed", "seed='1' is invalid")
    refused(lambda: parallel.step([0, 0]), InvalidType, "actions", "actions is a list")
    refused(lambda: parallel.step({"uav_0": 0}), InvalidOption, "actions", "no action for 'uav_1'")
    refused(lambda: parallel.step({"uav_0": 0, "uav_1": 0, "uav_7": 0}), InvalidOption, "actions", "'uav_7'")
    refused(lambda: parallel.step({"uav_0": 0, "uav_1": 1.5}), InvalidType, "actions", "has dtype float64")
