"""A fingerprint of the model's and the agents' behaviour: SHA-256 digests of what every setting produces.

Run it before and after a restructuring that must not change behaviour; the two outputs must be equal line for
line (on CPU, same torch, same machine)::

    python benchmarks/fingerprint.py > before.txt
    ...change the code...
    python benchmarks/fingerprint.py > after.txt && diff before.txt after.txt

Each line is ``<case> <digest>``: the World's outputs over a seeded random walk (every preset, channel, fading,
reward, layout and episode rule), the TorchRL environment's rollout, the exact optimum, and each agent's training
metrics, checkpoint and greedy evaluation after a few iterations; then the same for the energy models, then for
recharging and spares.
"""

from __future__ import annotations

import hashlib
import logging
import platform
import sys

import torch
from hydra import compose, initialize_config_dir

from uavrl.agents import agent_class
from uavrl.config import config_dir, model_config
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.world import World

WORLD_CASES = {
    "paper-n1": ("paper", dict(num_uavs=1)),
    "paper-n2": ("paper", dict()),
    "paper-n3": ("paper", dict(num_uavs=3, grid=(5, 4))),
    "paper-n2-rayleigh": ("paper", dict(fading="rayleigh")),
    "paper-n3-rayleigh-direct": ("paper", dict(num_uavs=3, fading="rayleigh", direct_links=True)),
    "paper-n2-best": ("paper", dict(reward="best_so_far")),
    "paper-n3-loggap": ("paper", dict(num_uavs=3, reward="log_gap")),
    "paper-n2-loggap-rayleigh": ("paper", dict(reward="log_gap", fading="rayleigh")),
    "paper-n2-random": ("paper", dict(layout="random")),
    "paper-n3-random-loggap": ("paper", dict(num_uavs=3, layout="random", reward="log_gap")),
    "paper-n2-keep-sensing": ("paper", dict(reset_positions="keep", init_tasks="sensing")),
    "paper-n2-tasks-state": ("paper", dict(state_includes_tasks=True, init_tasks="relaying", max_steps=7)),
    "paper-n2-nolease-betas": ("paper", dict(lease_rule=False, beta1=0.5, beta2=2.0)),
    "paper-n2-altitude": ("paper", dict(altitude=3.5, cell_size=7.0, alpha=2.5)),
    "reference_code-n2": ("reference_code", dict()),
    "reference_code-n3-delta": ("reference_code", dict(num_uavs=3, reward="delta")),
    "a2g_urban": ("a2g_urban", dict()),
    "a2g_urban-los_nlos": ("a2g_urban", dict(fading="los_nlos")),
    "a2g_urban-rayleigh-loggap": ("a2g_urban", dict(fading="rayleigh", reward="log_gap")),
    "a2g_urban-highrise-random": ("a2g_urban", dict(environment="highrise", layout="random", num_uavs=3)),
    "tr36777_uma": ("a2g_urban", dict(channel="tr36777_uma", num_uavs=4)),
    "tr36777_uma-los_nlos": ("a2g_urban", dict(channel="tr36777_uma", fading="los_nlos", num_uavs=4)),
    "paper-n3-rician": ("paper", dict(num_uavs=3, fading="rician", rician_k_db=6.0)),
    "a2g_urban-rician-loggap": ("a2g_urban", dict(fading="rician", reward="log_gap", num_uavs=3)),
    "tr36777_umi-los_nlos": ("a2g_urban", dict(channel="tr36777_umi", fading="los_nlos", num_uavs=4)),
    "tr36777_rma-30m": ("a2g_urban", dict(channel="tr36777_rma", altitude_m=30.0, num_uavs=4)),
}
# energy models (docs/model.md, Energy and lifetime): batteries small enough that UAVs leave service within the walk
ENERGY_WORLD_CASES = {
    "paper-n2-rotary": ("paper", dict(energy="rotary_wing", base=(-1, 0), battery_wh=0.6)),
    "paper-n3-rotary-uniform-rayleigh-random": (
        "paper",
        dict(
            num_uavs=3,
            energy="rotary_wing",
            base=(-1, -1),
            battery_wh=0.7,
            battery_init="uniform",
            fading="rayleigh",
            layout="random",
        ),
    ),
    "paper-n3-follow_up-uniform-loggap": (
        "paper",
        dict(num_uavs=3, energy="follow_up", base=(6, 2), battery_init="uniform", reward="log_gap"),
    ),
    "a2g_urban-rotary-los_nlos": (
        "a2g_urban",
        dict(grid=(5, 5), num_uavs=3, energy="rotary_wing", base=(-1, 0), battery_wh=5.0, fading="los_nlos"),
    ),
}
# recharging and spares, recorded after every line above
RECHARGE_WORLD_CASES = {
    "paper-n2-rotary-recharge-spare": (
        "paper",
        dict(energy="rotary_wing", base=(-1, 0), battery_wh=0.6, recharge_steps=3, num_spares=1),
    ),
    "paper-n3-follow_up-recharge-2spares-random": (
        "paper",
        dict(num_uavs=3, energy="follow_up", base=(6, 2), recharge_steps=2, num_spares=2, layout="random"),
    ),
}
STEPS, WORLDS = 25, 6

AGENT_CASES = {
    "tabular-numba": ["agent=tabular", "agent.episodes=3", "env.max_steps=60", "agent.runs=2"],
    "tabular-torch": ["agent=tabular", "agent.episodes=3", "env.max_steps=60", "agent.runs=2", "agent.backend=torch"],
    "tabular-shared-best": [
        *("agent=tabular", "agent.episodes=2", "env.max_steps=40", "agent.runs=3", "agent.shared_table=true"),
        "env.reward=best_so_far",
    ],
    "tabular-n3-tasks": [
        "agent=tabular",
        "agent.episodes=2",
        "env.max_steps=40",
        "env.num_uavs=3",
        "env.init_tasks=sensing",
    ],
    "tabular-value_iteration": ["agent=tabular", "agent.method=value_iteration", "env.grid=[3,3]"],
    "dqn-vdn": [
        *("agent=dqn", "agent.iterations=3", "env.max_steps=8", "agent.worlds=8", "agent.hidden=16"),
        *("agent.batch_size=32", "agent.buffer_size=100", "agent.updates=2", "agent.learning_starts=16"),
    ],
    "dqn-qmix-delta-n3": [
        *("agent=dqn", "agent.iterations=3", "env.max_steps=8", "agent.worlds=8", "agent.hidden=16"),
        *("agent.batch_size=32", "agent.buffer_size=100", "agent.updates=2", "agent.learning_starts=16"),
        *("agent.mixer=qmix", "agent.objective=delta", "env.num_uavs=3"),
    ],
    "dqn-joint-random-layout": [
        *("agent=dqn", "agent.iterations=2", "env.max_steps=8", "agent.worlds=8", "agent.hidden=16"),
        *("agent.batch_size=32", "agent.buffer_size=100", "agent.updates=2", "agent.learning_starts=16"),
        *("agent.head=joint", "env.layout=random"),
    ],
    "dqn-a2g-los_nlos": [
        *("agent=dqn", "agent.iterations=2", "env.max_steps=6", "agent.worlds=4", "agent.hidden=16"),
        *("agent.batch_size=16", "agent.buffer_size=40", "agent.updates=1", "agent.learning_starts=8"),
        *("env=a2g_urban", "env.num_uavs=3", "env.grid=[5,5]", "env.fading=los_nlos"),
    ],
    "dqn-rician": [
        *("agent=dqn", "agent.iterations=2", "env.max_steps=8", "agent.worlds=8", "agent.hidden=16"),
        *("agent.batch_size=32", "agent.buffer_size=100", "agent.updates=2", "agent.learning_starts=16"),
        *("env.fading=rician", "env.num_uavs=3"),
    ],
    "random": ["agent=random"],
    "oracle": ["agent=oracle", "env.num_uavs=3"],
    "oracle-a2g": ["agent=oracle", "env=a2g_urban", "env.num_uavs=3", "env.grid=[5,5]"],
}
ENERGY_AGENT_CASES = {
    "dqn-rotary": [
        *("agent=dqn", "agent.iterations=3", "env.max_steps=8", "agent.worlds=8", "agent.hidden=16"),
        *("agent.batch_size=32", "agent.buffer_size=100", "agent.updates=2", "agent.learning_starts=16"),
        *("env.energy=rotary_wing", "env.base=[-1,0]", "env.battery_wh=0.5"),
    ],
}
RECHARGE_AGENT_CASES = {
    "dqn-rotary-recharge": [
        *("agent=dqn", "agent.iterations=3", "env.max_steps=8", "agent.worlds=8", "agent.hidden=16"),
        *("agent.batch_size=32", "agent.buffer_size=100", "agent.updates=2", "agent.learning_starts=16"),
        *("env.energy=rotary_wing", "env.base=[-1,0]", "env.battery_wh=0.5", "env.recharge_steps=2"),
    ],
    "oracle-follow_up-recharge": ["agent=oracle", "env.energy=follow_up", "env.base=[-1,0]", "env.recharge_steps=2"],
}
COMMON = ["env.grid=[4,4]", "eval.num_starts=4", "progress=false"]


def machine_key() -> str:
    """What the digests depend on beside the code: torch's version, the processor and its vector instructions (torch's
    kernels round differently with AVX2 and AVX512)."""
    return f"torch {torch.__version__} on {platform.machine()} {torch.backends.cpu.get_cpu_capability()}"


def digest(value, h=None):
    """SHA-256 over tensors (dtype, shape, bytes), numbers, strings and nested containers, in a fixed order."""
    top = h is None
    h = hashlib.sha256() if top else h
    if isinstance(value, torch.Tensor):
        t = value.detach().cpu().contiguous().reshape(-1)
        h.update(f"{t.dtype}{tuple(value.shape)}".encode())
        h.update(t.view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    elif hasattr(value, "to_dict") and not isinstance(value, dict):
        digest(value.to_dict(), h)
    elif isinstance(value, dict):
        for key in sorted(value, key=str):
            if str(key).endswith("seconds") or str(key).endswith("_s"):  # wall-clock figures differ run to run
                continue
            h.update(str(key).encode())
            digest(value[key], h)
    elif isinstance(value, (list, tuple)):
        for item in value:
            digest(item, h)
    else:
        h.update(repr(value).encode())
    return h.hexdigest()[:16] if top else h


def world_case(preset: str, options: dict) -> dict[str, str]:
    cfg = make_config(preset, **{"max_steps": 10, **options})
    out = {}
    world = World(cfg, batch_size=WORLDS, seed=7)
    g = torch.Generator().manual_seed(1)
    seen = [world.reset()]
    for _ in range(STEPS):
        action = torch.randint(0, cfg.num_actions, (WORLDS, cfg.fleet_size), generator=g)
        step, reward, done = world.step(action)
        seen.append((step, reward, done))
        if done.any():
            seen.append(world.reset(done.nonzero().squeeze(-1)))
    out["world"] = digest(seen)
    out["optimum"] = digest(world.optimum())
    env = UAVSpectrumEnv(batch_size=WORLDS, seed=3, **{k: getattr(cfg, k) for k in options} | {"preset": preset})
    torch.manual_seed(0)
    out["env"] = digest(env.rollout(12, break_when_any_done=False))
    return out


def agent_case(overrides: list[str]) -> dict[str, str]:
    with initialize_config_dir(config_dir=config_dir(), version_base=None):
        cfg = compose(config_name="config", overrides=[*COMMON, *overrides])
    env_cfg = model_config(cfg)
    agent = agent_class(cfg.agent.name, cfg.agent)(env_cfg, cfg, torch.device("cpu"), 5)
    metrics = [agent.train_iteration() for _ in range(agent.num_iterations)]
    checkpoint = digest(agent.state_dict())  # before the evaluation, as a checkpoint is written
    evaluation = agent.evaluate(env_cfg, num_starts=4, horizon=12, seed=11, device="cpu", gamma=0.9)
    return {"train": digest(metrics), "checkpoint": checkpoint, "evaluate": digest(evaluation)}


def main() -> None:
    torch.set_num_threads(1)
    logging.getLogger("torchrl").setLevel(logging.WARNING)  # its storage messages would land among the digests
    print(f"# {machine_key()}")
    only = sys.argv[1:]
    # the energy cases come after the others, so the earlier lines keep their places in the recorded file
    groups = [
        ("world", WORLD_CASES, world_case),
        ("agent", AGENT_CASES, agent_case),
        ("world", ENERGY_WORLD_CASES, world_case),
        ("agent", ENERGY_AGENT_CASES, agent_case),
        ("world", RECHARGE_WORLD_CASES, world_case),
        ("agent", RECHARGE_AGENT_CASES, agent_case),
    ]
    for kind, cases, run in groups:
        for name, case in cases.items():
            if not only or name in only:
                for part, value in (run(*case) if kind == "world" else run(case)).items():
                    print(f"{kind}:{name}:{part} {value}", flush=True)


if __name__ == "__main__":
    main()
