"""The batched TorchRL environment of the UAV spectrum-sharing model (docs/model.md).

:class:`UAVSpectrumEnv` is a thin ``EnvBase`` over a :class:`~uavrl.envs.world.World`
(the physics, no TorchRL): it owns the specs, the keys, seeding and resets,
checks the actions, and wraps each step's tensors in a TensorDict.
"""

from __future__ import annotations

import functools
import numbers

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Bounded, Categorical, Composite, Unbounded
from torchrl.data.utils import ACTION_SPACE_MAP
from torchrl.envs import EnvBase

from .config import (
    RETURN,
    ModelConfig,
    action_names,
    check_config_alone,
    make_config,
)
from .errors import InvalidOption, InvalidType
from .limits import DEFAULT_MEMORY_BUDGET, env_bytes, frame_bytes, gib
from .physics.sensing import MESSAGE_BOUND
from .render import render as draw_world
from .world import DIAGNOSTICS, SEED_LIMIT, World, check_batch_size, check_memory, check_seed, resolve_device

__all__ = ["SEED_LIMIT", "MaskedCategorical", "UAVSpectrumEnv", "check_seed", "resolve_device"]


class MaskedCategorical(Categorical):
    """TorchRL's ``Categorical`` with a cheaper masked ``rand``: one uniform per draw picks among the allowed actions.

    Each allowed action is equally likely, as with ``Categorical``'s ``torch.multinomial`` (which TorchRL's
    ``ActionMask`` transform and ``EGreedyModule`` call on every step).  A mask of ``n <= 8`` actions is read as a
    number (its pattern), and a table of every pattern's allowed actions turns ``floor(u * allowed)`` into the
    action: at 4096 x 2 masks of 6 actions a third of the cost of drawing a uniform per action (the rule before),
    a sixth of ``torch.multinomial``'s.  Unmasked, it is ``Categorical``.

    Example:
        >>> spec = MaskedCategorical(6, (3,), mask=torch.tensor([[1, 0, 0, 1, 0, 0]] * 3, dtype=torch.bool))
        >>> sorted(set(spec.rand((1000,)).flatten().tolist()))
        [0, 3]
    """

    _PATTERN_LIMIT = 8  # masks of more actions draw one uniform per action instead

    def rand(self, shape: torch.Size | None = None) -> torch.Tensor:
        if self.mask is None:
            return super().rand(shape)
        mask = self.mask if shape is None else self.mask.expand(*shape, *self.mask.shape)
        n = mask.shape[-1]
        if n > self._PATTERN_LIMIT:
            noise = torch.rand(mask.shape, device=mask.device).masked_fill_(~mask, -1.0)
            return noise.argmax(-1).to(self.dtype)
        allowed, actions = _mask_patterns(n, mask.device)
        pattern = torch.mv(mask.reshape(-1, n).to(torch.float32), 2.0 ** torch.arange(n, device=mask.device)).long()
        u = torch.rand(pattern.shape, device=mask.device)
        pick = actions.take(pattern * n + (u * allowed.take(pattern)).long())
        return pick.view(mask.shape[:-1]).to(self.dtype)


@functools.lru_cache(maxsize=8)
def _mask_patterns(n: int, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """For every mask of ``n`` actions read as the number ``sum_a mask[a] 2^a``: how many actions it allows
    ``[2^n]``, and its allowed actions in order, flat ``[2^n * n]`` (zeros after them)."""
    patterns = torch.arange(2**n)
    allows = (patterns[:, None] >> torch.arange(n)) & 1  # [2^n, n]
    order = (1 - allows).argsort(dim=-1, stable=True)  # allowed actions first, each group ascending
    return allows.sum(-1).to(device), torch.where(allows.gather(-1, order) == 1, order, 0).flatten().to(device)


_DONE_KEYS = ("done", "terminated", "truncated")
ACTION_KEY = "('agents', 'action')"  # how the one-line errors name the action
MESSAGE_KEY = "('agents', 'message')"
# the keywords TorchRL's own code passes to reset (EnvBase.reset, rollouts, collectors), besides seed
TORCHRL_RESET_KEYWORDS = ("seed", "set_state", "select_reset_only")

# TorchRL looks action spaces up by exact type (QValueModule, DQN losses, BenchMARL's Q-learners)
ACTION_SPACE_MAP.setdefault(MaskedCategorical, "categorical")


class UAVSpectrumEnv(EnvBase):
    """TorchRL's view of ``B`` worlds of N UAVs that relay for a primary link or sense for an emergency centre.

    Each step every UAV takes one of 6 actions (0 up, 1 down, 2 left, 3 right,
    4 sensing task, 5 relaying task); the team reward is the change of
    ``beta1 R_PU + beta2 R_SE`` (``reward="delta"``) or the authors'
    best-so-far reward.  Episodes end by truncation after ``max_steps``.

    Keys follow TorchRL's multi-agent convention: a group ``"agents"`` of batch
    ``[B, N]`` with ``observation``, ``action`` and ``action_mask``; at the root
    ``reward``, ``done``/``terminated``/``truncated``, a global ``state``, the
    integer views ``positions`` ``[B, N, 2]`` (x, y), ``tasks`` ``[B, N]`` and
    ``state_index`` ``[B, 1]`` (when the tabular state fits in int64), and the
    step's ``r_pu``, ``r_se``, ``utility``, ``moves``, ``task_switches``, each
    ``[B, 1]`` like ``reward`` (so ``CatTensors`` joins them with ``state``).
    With ``layout="random"`` also ``nodes`` ``[B, 4, 3]``: each world's PT, PR,
    S, E (x, y, z) in cell units, float64, what its layout tables are computed
    from (the oracle plans on them; ``state`` holds them scaled, in float32).
    As VMAS's TorchRL wrapper, the env has ``n_agents``, ``agent_names``
    (``agent_0`` ...) and ``group_map`` (``{"agents": agent_names}``).

    World ``i`` draws its randomness from its own stream seeded ``seed + i``, so
    it behaves exactly like world 0 of a batch of one seeded ``seed + i``.

    Args:
        batch_size: number of independent worlds ``B``.
        grid: ``(L1, L2)`` cells.
        num_uavs: ``N``, at most ``L1 * L2``.
        preset: ``"paper"``, ``"reference_code"`` (docs/model.md, The authors' code as a preset) or
            ``"a2g_urban"`` (docs/model.md, Channel models); ``grid`` and ``num_uavs`` given here win over the
            preset's (``config=make_config("a2g_urban")`` keeps its 10x10 and 6 UAVs).
        seed: seed of world 0.
        device: where the worlds live.
        max_steps: episode length ``T``.
        config: a complete :class:`~uavrl.envs.config.ModelConfig`; replaces
            ``grid``, ``num_uavs``, ``preset``, ``max_steps`` and the overrides.
        diagnostics: also return the step's ``r_pu``, ``r_se``, ``utility``,
            ``moves``, ``task_switches`` and ``state_index``
            (:data:`~uavrl.envs.world.DIAGNOSTICS`).  ``False`` leaves the keys
            an agent acts and learns from (observation, mask, state,
            positions, tasks, nodes, reward, done): a lighter rollout, for
            training loops that read nothing else (BenchMARL's task does this).
        agent_rewards: publish the reward as VMAS's wrapper does, under the
            group: ``("agents", "reward")`` ``[B, N, 1]``, every UAV receiving
            the team reward (so the mean over the UAVs is the team reward), is
            then the only reward key.  The done keys stay at the root
            ``[B, 1]``, as VMAS's: per-agent losses read them expanded to the
            reward's shape (``done.unsqueeze(-1).expand_as(reward)``, what
            TorchRL's multi-agent examples do in their ``DoneTransform``),
            which a group copy in the env's output would break (the
            collector's reused buffer then holds the expanded view).
            ``False`` (default): the team reward at the root, ``[B, 1]``.
        memory_budget: bytes the worlds may take (:func:`~uavrl.envs.limits.world_bytes`); a larger
            ``batch_size`` is refused before anything is allocated.
        **overrides: any :class:`~uavrl.envs.config.ModelConfig` option
            (``layout``, ``fading``, ``reward``, powers, ...).

    Example:
        >>> env = UAVSpectrumEnv(batch_size=4, grid=(6, 6), num_uavs=2, max_steps=10)
        >>> td = env.rollout(10)
        >>> td["next", "utility"].shape
        torch.Size([4, 10, 1])
        >>> u_star, positions, tasks = env.optimum()
    """

    batch_locked = True

    def __init__(
        self,
        batch_size=1,
        grid=(6, 6),
        num_uavs=2,
        preset="paper",
        seed=0,
        device="cpu",
        max_steps=100,
        *,
        config: ModelConfig | None = None,
        diagnostics: bool = True,
        agent_rewards: bool = False,
        memory_budget: int = DEFAULT_MEMORY_BUDGET,
        **overrides,
    ):
        if config is not None and not isinstance(config, ModelConfig):
            raise InvalidType("config", config, "give a ModelConfig (uavrl.envs.make_config(...)) or None")
        check_config_alone(config, overrides, grid=grid, num_uavs=num_uavs, preset=preset, max_steps=max_steps)
        if not isinstance(diagnostics, bool):
            raise InvalidType("diagnostics", diagnostics, "give True or False")
        cfg = config or make_config(preset, grid=grid, num_uavs=num_uavs, max_steps=max_steps, **overrides)
        B = check_batch_size(batch_size)
        if not isinstance(agent_rewards, bool):
            raise InvalidType("agent_rewards", agent_rewards, "give True or False")
        check_memory(cfg, B, memory_budget, env_bytes)
        super().__init__(device=resolve_device(device), batch_size=torch.Size([B]))
        self.cfg: ModelConfig = cfg
        self.num_worlds, self.num_uavs = B, cfg.fleet_size  # spares are agents too
        self.num_actions = cfg.num_actions
        self.agent_rewards = agent_rewards
        self.memory_budget = memory_budget  # a rollout's steps are held too
        self.world = World(cfg, B, self.device, seed, diagnostics=diagnostics, memory_budget=memory_budget)
        self._make_specs()
        self.set_seed(seed)

    # --------------------------------------------------- TorchRL's multi-agent names
    @property
    def n_agents(self) -> int:
        """The number of UAVs ``N`` (VMAS's name)."""
        return self.num_uavs

    @property
    def agent_names(self) -> list[str]:
        """``agent_0`` ... ``agent_{N-1}``: UAV ``i`` is row ``i`` of the group ``"agents"``."""
        return [f"agent_{i}" for i in range(self.num_uavs)]

    @property
    def group_map(self) -> dict[str, list[str]]:
        """Every UAV in one group ``"agents"`` (TorchRL's ``MarlGroupMapType.ALL_IN_ONE_GROUP``)."""
        return {"agents": self.agent_names}

    def to(self, device) -> UAVSpectrumEnv:
        """Move the env, its specs and its worlds (:meth:`World.to`) to ``device``."""
        device = resolve_device(device)
        super().to(device)
        self.world.to(self.device)
        return self

    # ------------------------------------------------------------------ specs
    @property
    def observation_size(self) -> int:
        """Per-UAV features: own (x, y, task), contributions at the own and 4 next cells, the others' (x, y, task).

        The 4 nodes' positions, the same for every UAV of a world, are the last 12 entries of ``state``
        (:func:`~uavrl.envs.world.observation_with_nodes` appends them to each UAV's observation)."""
        return self.world.observation_size

    @property
    def state_size(self) -> int:
        return self.world.state_size

    def _make_specs(self):
        N, A = self.num_uavs, self.num_actions
        agents = Composite(
            observation=Unbounded((N, self.observation_size), dtype=torch.float32, device=self.device),
            action_mask=Binary(n=A, shape=(N, A), dtype=torch.bool, device=self.device),
            shape=(N,),
            device=self.device,
        )
        if self.cfg.local:  # whether each UAV's move at the last step was cancelled: what it knows of itself
            agents["cancelled"] = Categorical(2, (N,), dtype=torch.bool, device=self.device)
        obs = Composite(
            agents=agents,
            state=Unbounded((self.state_size,), dtype=torch.float32, device=self.device),
            positions=Unbounded((N, 2), dtype=torch.long, device=self.device),
            tasks=Categorical(2, (N,), dtype=torch.long, device=self.device),
            device=self.device,
        )
        if self.cfg.num_levels > 1:  # each UAV's altitude level, 0 the lowest
            obs["levels"] = Categorical(self.cfg.num_levels, (N,), dtype=torch.long, device=self.device)
        if self.world.diagnostics:
            for key in ("r_pu", "r_se", "utility"):
                obs[key] = Unbounded((1,), dtype=torch.float32, device=self.device)
            for key in ("moves", "task_switches"):
                obs[key] = Unbounded((1,), dtype=torch.long, device=self.device)
            if self.world.state_index_fits:
                obs["state_index"] = Unbounded((1,), dtype=torch.long, device=self.device)
        if self.cfg.layout == "random":  # not a diagnostic: the oracle plans on each world's layout
            obs["nodes"] = Unbounded((4, 3), dtype=torch.float64, device=self.device)

        self.full_observation_spec_unbatched = obs
        actions = {"action": MaskedCategorical(A, (N,), dtype=torch.long, device=self.device)}
        if self.cfg.message_size:  # what each UAV sends those within range (docs/model.md, Local observations)
            shape = (N, self.cfg.message_size)
            actions["message"] = Bounded(-MESSAGE_BOUND, MESSAGE_BOUND, shape, dtype=torch.float32, device=self.device)
        self.full_action_spec_unbatched = Composite(
            agents=Composite(actions, shape=(N,), device=self.device), device=self.device
        )
        if self.agent_rewards:  # one reward key, as on VMAS (env.reward_key is ("agents", "reward"))
            reward = Composite(
                agents=Composite(
                    reward=Unbounded((N, 1), dtype=torch.float32, device=self.device), shape=(N,), device=self.device
                ),
                device=self.device,
            )
        else:
            reward = Composite(reward=Unbounded((1,), dtype=torch.float32, device=self.device), device=self.device)
        self.full_reward_spec_unbatched = reward
        self.full_done_spec_unbatched = Composite(
            {k: Categorical(2, (1,), dtype=torch.bool, device=self.device) for k in _DONE_KEYS},
            device=self.device,
        )

    # --------------------------------------------------------------- seeding
    def _set_seed(self, seed: int | None):
        self.world.set_seed(seed)

    # ---------------------------------------------------------- reset, step
    # TorchRL's hooks: _reset and _step read and check their inputs (the action once per step, in _step); step,
    # reset and rollout are overridden only for what EnvBase reads before any hook (see each one's docstring).
    def _outputs(self, out: dict) -> TensorDictBase:
        """The world's outputs as this env's TensorDict: the per-UAV keys in the group ``"agents"``, the per-world
        scalars ``[B, 1]``; with ``agent_rewards`` the team reward copied to every UAV."""
        B, N, dev = self.num_worlds, self.num_uavs, self.device
        group = {"observation": out.pop("observation"), "action_mask": out.pop("action_mask")}
        if "cancelled" in out:
            group["cancelled"] = out.pop("cancelled")
        for key in DIAGNOSTICS:  # the world's per-world outputs [B], [B, 1] as TorchRL has a per-world reward or done
            if key in out:
                out[key] = out[key].unsqueeze(-1)
        if self.cfg.layout == "random":
            out["nodes"] = self.world.nodes
        if self.agent_rewards and "reward" in out:
            group["reward"] = out.pop("reward").unsqueeze(1).expand(B, N, 1).clone()
        if self.cfg.recharge_steps is not None:  # "return" is refused where not valid: random actions keep off it
            # the mask kept on the action spec, as TorchRL's PettingZoo wrapper keeps its groups' masks
            self.input_spec["full_action_spec", "agents", "action"].update_mask(group["action_mask"])
        out["agents"] = TensorDict._new_unsafe(group, batch_size=torch.Size((B, N)), device=dev)
        return TensorDict._new_unsafe(out, batch_size=self.batch_size, device=dev)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        """TorchRL's hook of ``reset``: ``kwargs`` are ``reset``'s keywords, ``seed`` and those TorchRL passes itself
        (:data:`TORCHRL_RESET_KEYWORDS`), any other refused in one line; ``tensordict``'s ``"_reset"`` mask, checked,
        names the worlds to reset (default all)."""
        unread = sorted(set(kwargs) - set(TORCHRL_RESET_KEYWORDS))
        if unread:
            name = unread[0]
            message = (
                f"reset() got {name}={kwargs[name]!r}: UAVSpectrumEnv.reset reads a tensordict (its '_reset' mask) "
                "and seed, nothing else"
            )
            raise InvalidOption(name, message=message)
        if "seed" in kwargs:
            self.set_seed(check_seed(kwargs["seed"]))
        B, dev = self.num_worlds, self.device
        mask = tensordict.get("_reset", None) if tensordict is not None else None
        if mask is not None:
            self._check_reset_mask(mask)
        worlds = None if mask is None else mask.reshape(B).to(dev).nonzero().squeeze(-1)
        out = self.world.reset(worlds)
        done = torch.zeros(B, 1, dtype=torch.bool, device=dev)
        out.update({"done": done, "terminated": done.clone(), "truncated": done.clone()})
        return self._outputs(out)

    def _check_reset_mask(self, mask: torch.Tensor) -> None:
        """A one-line error for a ``"_reset"`` mask that is not ``[B]`` or ``[B, 1]`` booleans on the CPU or a CUDA
        device (it is moved to the env's)."""
        B, shapes = self.num_worlds, ((self.num_worlds,), (self.num_worlds, 1))
        wrong = [
            f"shape {tuple(mask.shape)}" if tuple(mask.shape) not in shapes else "",
            f"dtype {mask.dtype}" if mask.dtype != torch.bool else "",
            f"device {mask.device}" if mask.device.type not in ("cpu", "cuda") else "",  # moved to the env's
        ]
        if any(wrong):
            raise InvalidOption(
                "_reset",
                message=f"'_reset' has {', '.join(w for w in wrong if w)}: expected [{B}] or [{B}, 1] booleans "
                "(one per world, True to reset it) on the CPU or a CUDA device",
            )

    def _check_action_tensor(self, action) -> None:
        """The action's type, shape, dtype and device, checked before the World reads it (a one-line error of
        :class:`~uavrl.envs.InvalidOption` naming ``('agents', 'action')``)."""
        key, shape = ACTION_KEY, (self.num_worlds, self.num_uavs)
        if not isinstance(action, torch.Tensor):
            raise InvalidType(
                key,
                message=f"{key} is a {type(action).__name__}: expected a tensor of {list(shape)} "
                f"integers {action_names(self.num_actions)}",
            )
        if tuple(action.shape) != shape:
            raise InvalidOption(key, message=f"{key} has shape {tuple(action.shape)}: expected {shape} (worlds, UAVs)")
        if action.dtype.is_floating_point or action.dtype.is_complex or action.dtype == torch.bool:
            raise InvalidType(
                key, message=f"{key} has dtype {action.dtype}: expected an integer dtype with values 0..5"
            )
        if action.device.type not in ("cpu", "cuda"):
            raise InvalidOption(
                key,
                message=f"{key} is on device {action.device}: expected the CPU or a CUDA device (the env's is "
                f"{self.device})",
            )

    def _check_action_values(self, action: torch.Tensor) -> None:
        """The action's values: each one of the UAV's actions, and "return" only for a UAV in service (on the grid:
        what its action_mask allows)."""
        lo, hi = torch.aminmax(action)
        if lo < 0 or hi >= self.num_actions:
            bad = (lo if lo < 0 else hi).item()
            message = f"('agents', 'action') holds {bad}: actions are {action_names(self.num_actions)}"
            raise InvalidOption(ACTION_KEY, message=message)
        if hi == RETURN and self.cfg.recharge_steps is not None:  # "return" is a serving UAV's only: on the grid
            # the World's cells, not the spec's mask: Categorical.to(device) drops the mask (env.to before a step)
            away = (action == RETURN) & (self.world.state.cell >= self.world.num_positions)
            if away.any():
                world, uav = (int(i) for i in away.nonzero()[0])
                raise InvalidOption(
                    ACTION_KEY,
                    message=f"('agents', 'action') sends UAV {uav} of world {world} home (6, return), but it does "
                    "not serve: return is valid only for a UAV in service (its action_mask)",
                )

    def _messages(self, tensordict: TensorDictBase) -> torch.Tensor | None:
        """The UAVs' messages ``("agents", "message")`` ``[B, N, message_size]`` (None: no message this step, zeros),
        checked: finite numbers; the World clips them to [-1, 1]."""
        if not self.cfg.message_size:
            return None
        message = tensordict.get(("agents", "message"), None)
        if message is None:
            return None
        shape = (self.num_worlds, self.num_uavs, self.cfg.message_size)
        if (
            not isinstance(message, torch.Tensor)
            or tuple(message.shape) != shape
            or not message.dtype.is_floating_point
        ):
            got = f"shape {tuple(message.shape)}, dtype {message.dtype}" if isinstance(message, torch.Tensor) else ""
            raise InvalidOption(
                MESSAGE_KEY,
                message=f"{MESSAGE_KEY} is {got or type(message).__name__}: expected {list(shape)} floats (worlds, "
                "UAVs, env.message_size)",
            )
        if not torch.isfinite(message).all():
            raise InvalidOption(MESSAGE_KEY, message=f"{MESSAGE_KEY} holds NaN or infinity: send finite numbers")
        return message.to(self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        """TorchRL's hook of ``step``: the action, checked once here (one-line errors of
        :class:`~uavrl.envs.InvalidOption` for a missing action, or one of the wrong type, shape, dtype, device or
        values), is every world's next step."""
        action = tensordict.get(("agents", "action"), None)
        if action is None:
            raise InvalidOption(
                ACTION_KEY,
                message=f"step() got no ('agents', 'action'): write every UAV's action there, [{self.num_worlds}, "
                f"{self.num_uavs}] integers {action_names(self.num_actions)}",
            )
        self._check_action_tensor(action)
        if not self.world.was_reset:
            raise RuntimeError(
                "UAVSpectrumEnv.step() before every world was reset: call env.reset() first (a world never reset has "
                "no UAV positions yet)"
            )
        self._check_action_values(action)
        out, reward, truncated = self.world.step(action, self._messages(tensordict))
        terminated, truncated = self.world.terminated.unsqueeze(-1), truncated.unsqueeze(-1)
        out["reward"] = reward.float().unsqueeze(-1)
        out["done"] = terminated | truncated
        out["terminated"] = terminated
        out["truncated"] = truncated
        return self._outputs(out)

    def step(self, tensordict: TensorDictBase) -> TensorDictBase:
        """TorchRL's ``step``, after a one-line error of :class:`~uavrl.envs.InvalidOption` for an input that is not a
        TensorDict of batch size ``[B]``.

        Overridden for that alone: ``EnvBase.step``'s first line, ``self._assert_tensordict_shape(tensordict)``, reads
        ``tensordict.batch_size`` before any hook (an ``AttributeError`` for a dict, TorchRL's ``RuntimeError`` for
        another batch size); the action is checked in :meth:`_step`.
        """
        if not isinstance(tensordict, TensorDictBase):
            raise InvalidType(
                "tensordict",
                message=f"step() got a {type(tensordict).__name__}: give the TensorDict "
                "that reset() or the last step returned, with ('agents', 'action') set",
            )
        if tensordict.batch_size != self.batch_size:
            raise InvalidOption(
                "tensordict",
                message=f"step() got a TensorDict of batch size {list(tensordict.batch_size)}: this env has "
                f"[B={self.num_worlds}] worlds, so ('agents', 'action') is [{self.num_worlds}, {self.num_uavs}]",
            )
        return super().step(tensordict)

    def reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        """TorchRL's ``reset`` (``tensordict``, ``kwargs``: as TorchRL's, read by :meth:`_reset`), after a one-line
        error for a ``tensordict`` that is neither ``None`` nor a TensorDict.

        Overridden for that alone: ``EnvBase.reset`` reads ``tensordict.batch_size``
        (``self._assert_tensordict_shape``) before any hook.  ``seed`` (a keyword) seeds the worlds first, as
        :meth:`set_seed` does (world ``i`` draws from ``seed + i``), so ``reset(seed=s)`` starts the same worlds as
        ``set_seed(s)`` then ``reset()``; any other keyword that TorchRL does not pass itself is refused in one line;
        so is a ``"_reset"`` mask that is not ``[B]`` or ``[B, 1]`` booleans.
        """
        if tensordict is not None and not isinstance(tensordict, TensorDictBase):
            raise InvalidType(
                "tensordict",
                message=f"reset() got a {type(tensordict).__name__}: give None or a "
                "TensorDict (with a '_reset' mask of the worlds to reset)",
            )
        return super().reset(tensordict, **kwargs)

    def rollout(self, max_steps: int, *args, **kwargs) -> TensorDictBase:
        """TorchRL's ``rollout`` (``args``, ``kwargs``: as TorchRL's, the policy first); one-line errors for
        ``max_steps < 1``, for a policy that is not callable, for more steps than ``memory_budget`` holds (every step
        of every world is kept: at most an episode's unless ``break_when_any_done=False``) and for a policy's action
        not ``[B, N]``.

        Overridden for those alone: ``EnvBase.rollout`` hands ``max_steps`` to no hook (it runs ``range(max_steps)``
        steps after a reset, and stacks no step at all for 0), and the policy writes its action into the ``"agents"``
        group inside the rollout's loop, where tensordict refuses a wrong shape before ``step`` is called.
        """
        policy = args[0] if args else kwargs.get("policy")
        if policy is not None and not callable(policy):
            raise InvalidType(
                "policy", policy, "give a TorchRL policy (a module that writes ('agents', 'action')), or None"
            )
        if not isinstance(max_steps, numbers.Integral) or isinstance(max_steps, bool) or max_steps < 1:
            message = f"rollout(max_steps={max_steps!r}) is invalid: give a whole number of steps >= 1"
            raise (InvalidOption if isinstance(max_steps, numbers.Real) else InvalidType)("max_steps", message=message)
        ends = kwargs.get("break_when_any_done", True) or kwargs.get("break_when_all_done", False)
        steps = min(max_steps, self.cfg.max_steps) if ends else max_steps  # an episode ends at cfg.max_steps
        need = steps * self.num_worlds * frame_bytes(self.cfg)
        if need > self.memory_budget:
            message = (
                f"rollout(max_steps={max_steps!r}) is invalid: {steps:,} steps of {self.num_worlds:,} worlds need "
                f"about {gib(need)}, over memory_budget={int(self.memory_budget):,} bytes: use fewer steps, or raise "
                "the env's memory_budget"
            )
            raise InvalidOption("max_steps", message=message)
        try:
            return super().rollout(max_steps, *args, **kwargs)
        except RuntimeError as err:
            if "batch dimension mismatch" not in str(err):
                raise
            # tensordict refused the policy's action: the "agents" group is [B, N], so the action must be too
            expected = f"[B={self.num_worlds}, N={self.num_uavs}] (worlds, UAVs)"
            refusal = str(err).splitlines()[0]
            message = f"the policy wrote ('agents', 'action') not {expected}: {refusal}"
            raise InvalidOption(ACTION_KEY, message=message) from err

    render_mode = "rgb_array"  # frames come back as arrays (VMAS's and Gymnasium's name); no window opens

    def render(self, mode: str = "rgb_array", env_index=0, agent_index_focus: int | None = None):
        """VMAS's ``render``: an ``[H, W, 3]`` uint8 picture of world ``env_index`` now, or of a list of worlds tiled.

        It shows the grid, the nodes, each UAV coloured by task with the links it serves, and the step's utility
        against U* (:mod:`uavrl.envs.render`); ``agent_index_focus`` rings one UAV.  ``mode``: ``"rgb_array"``, the
        only one.
        """
        return draw_world(self.world, mode, env_index, agent_index_focus)

    # ------------------------------------------------------ the world's helpers
    def cells_of(self, positions: torch.Tensor) -> torch.Tensor:
        """Cell indices ``y * L1 + x`` of ``[..., 2]`` (x, y) positions."""
        return self.world.cells_of(positions)

    def utility(self, positions: torch.Tensor, tasks: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(R_PU, R_SE, U)`` of configurations of this env's worlds (:meth:`World.utility`): the UAVs' ``positions``
        ``[B, N, 2]`` and ``tasks`` ``[B, N]``."""
        return self.world.utility(positions, tasks)

    def optimum(self, method: str = "auto") -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Exact ``U*`` ``[B]`` and one optimal configuration per world (:meth:`World.optimum`; ``method`` as
        :func:`uavrl.envs.solvers.optimum.optimum`'s)."""
        return self.world.optimum(method)

    def joint_action_mask(self, positions: torch.Tensor | None = None) -> torch.Tensor:
        """``[B, 6^N]`` valid joint actions (all cells on the grid and distinct) at ``positions`` (default: now)."""
        return self.world.joint_action_mask(positions)

    def model_config(self) -> ModelConfig:
        """The model's options: a method, so a ``SerialEnv`` or ``ParallelEnv`` returns every worker's."""
        return self.cfg

    def layout_tables(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``(cell_contributions, direct)``: a method, so a ``SerialEnv`` or ``ParallelEnv`` returns every worker's."""
        return self.cell_contributions, self.direct

    @property
    def cell_contributions(self) -> torch.Tensor:
        """``[B, C, 2]`` per-cell relay (PU) and sensing (SE) contributions, deterministic channels."""
        return self.world.cell_contributions

    @property
    def direct(self) -> torch.Tensor:
        """``[B, 2]`` direct-link SNRs (PT->PR, S->E)."""
        return self.world.direct

    @property
    def neighbours(self) -> torch.Tensor:
        """``[C, 4]`` target cell of each move, -1 off the grid."""
        return self.world.neighbours
