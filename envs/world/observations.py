"""What the World shows an agent: each UAV's observation and each world's state, assembled from the per-code
tables of :mod:`.tables` (:class:`Observations`, a part of :class:`~uavrl.envs.world.World`), and the outputs of a
reset or a step.

A UAV's observation is its own (x, y, task), the contributions at its cell and the 4 next cells, then the others'
(x, y, task) (under an energy model then the batteries and service flags; with altitude levels then its level, the
contributions a climb and a descent reach and the others' levels); a world's state is every UAV's (x, y, task) and
contributions at its cell (and battery, service flag, level), then the 4 nodes' positions (:data:`NODE_FEATURES`
entries).
"""

from __future__ import annotations

import torch

from ..limits import NODE_FEATURES, model_observation_size, state_size
from ..physics.channel import link_gains, relay_contributions

# outputs that describe a step rather than the configuration an agent acts from (World(diagnostics=False) skips them)
DIAGNOSTICS = ("r_pu", "r_se", "utility", "moves", "task_switches", "state_index")


def observation_with_nodes(observation: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
    """``[*, N, F + 12]``: each UAV's observation followed by its world's node positions (the last 12 of ``state``).

    The nodes are the same for every UAV of a world, so the observation leaves
    them out; a network that wants them beside each UAV's features builds this input.
    """
    nodes = state[..., None, -NODE_FEATURES:]
    return torch.cat([observation, nodes.expand(*observation.shape[:-1], NODE_FEATURES)], -1)


def _others(x: torch.Tensor) -> torch.Tensor:
    """``[W, N, N - 1, ...]`` each UAV's others of ``x`` ``[W, N, ...]``, in the order ``i+1, ..., i+N-1`` (mod N): a
    window over the rows twice (a view, no gather)."""
    W, N, *rest = x.shape
    inner = x[0, 0].numel()
    twice = torch.cat([x, x], 1)
    return twice.as_strided((W, N, N - 1, *rest), (2 * N * inner, inner, inner, *twice.stride()[2:]), inner)


class Observations:
    """The World's observation assembly (a mixin of :class:`~uavrl.envs.world.World`): it reads the World's parts
    (``dynamics``, ``energy``), its per-code tables (:class:`~.tables.LayoutTables`) and its state."""

    @property
    def observation_size(self) -> int:
        """Per-UAV features: own (x, y, task), contributions at the own and 4 next cells, the others' (x, y, task);
        under an energy model then its battery (a fraction of the capacity) and service flag, and the others', in
        the same order as their (x, y, task).

        The 4 nodes' positions are the same for every UAV of a world: they are the last
        :data:`NODE_FEATURES` entries of the world's ``state`` (:func:`observation_with_nodes`)."""
        return model_observation_size(self.cfg)

    @property
    def state_size(self) -> int:
        """Per UAV (x, y, task) and its contributions at its cell (under an energy model then per UAV its battery and
        service flag), then the 4 nodes' (x, y, z)."""
        return state_size(self.num_uavs, self.energy is not None, self.cfg.num_levels > 1)

    def _assemble(
        self,
        code: torch.Tensor,
        energy: torch.Tensor | None = None,
        tables: tuple | None = None,
        messages: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(observation [W, N, F], state [W, S])`` of ``W`` configurations (one per world, or any ``W`` for a fixed
        layout); under an energy model ``energy`` ``[W, N, 2]`` their features (default: the worlds' batteries now);
        ``tables`` ``(code_obs, node_obs, code_vertical)`` of their own layouts (:meth:`_observation_tables`; default:
        the worlds'); a local observation reads their ``messages`` (default: the worlds')."""
        W, N = code.shape
        code_obs, node_obs = (self._code_obs, self._node_obs) if tables is None else tables[:2]
        own = self._code_rows(code_obs, code)  # [W, N, 13]: x, y, task, 10 contributions
        per_uav = [own[..., :5].reshape(W, 5 * N)]
        if self.energy is not None:
            energy = self.energy.features(self._s) if energy is None else energy  # [W, N, 2]
            per_uav.append(energy.reshape(W, 2 * N))
        vertical = level = None
        if self._code_level is not None:
            vertical = self._code_rows(self._code_vertical if tables is None else tables[2], code)
            level = self._code_level.index_select(0, code.view(-1)).view(W, N)
            per_uav.append(level)
        state = torch.cat([*per_uav, node_obs.expand(W, NODE_FEATURES)], -1)
        if self.cfg.local:
            messages = self._s.messages if messages is None else messages
            return self._local(code, own, energy, vertical, level, messages), state
        return self._central(code, own, energy, vertical, level), state

    def _central(self, code, own, energy, vertical, level) -> torch.Tensor:
        """``[W, N, F]`` the central observations: each UAV's own part, the others' (x, y, task), under an energy model
        its and the others' battery and service flag, with altitude levels its vertical part and the others' levels;
        the others in the order ``i+1, ..., i+N-1`` (mod N), a window over the rows twice."""
        W, N = code.shape
        parts = [own]
        if N == 2:  # the other UAV's (x, y, task)
            parts.append(self._code_xyt.index_select(0, code.flip(-1).view(-1)).view(W, N, 3))
        elif N > 2:
            xyt = self._code_xyt.index_select(0, torch.cat([code, code], 1).view(-1))  # [2 W N, 3]
            parts.append(xyt.as_strided((W, N, 3 * (N - 1)), (6 * N, 3, 1), 3))
        if energy is not None:
            parts.append(energy)
            if N == 2:
                parts.append(energy.flip(1))
            elif N > 2:
                parts.append(torch.cat([energy, energy], 1).as_strided((W, N, 2 * (N - 1)), (4 * N, 2, 1), 2))
        if vertical is not None:
            parts.append(vertical)
            if N > 1:
                parts.append(torch.cat([level, level], 1).as_strided((W, N, N - 1), (2 * N, 1, 1), 1))
        return torch.cat(parts, -1) if len(parts) > 1 else own

    def _local(self, code, own, energy, vertical, level, messages) -> torch.Tensor:
        """``[W, N, F]`` the local observations (:mod:`uavrl.envs.physics.sensing`): each UAV's own part and the nodes
        it hears (``own``, the per-code table's), under an energy model its battery and service flag, with altitude
        levels its vertical part, then a slot per other UAV in the order ``i+1, ..., i+N-1`` (mod N), zeros for one
        beyond ``comm_radius``."""
        W, N = code.shape
        parts = [own, *([] if energy is None else [energy]), *([] if vertical is None else [vertical])]
        if N == 1:
            return torch.cat(parts, -1)
        send = self._send_key.index_select(0, code.view(-1)).view(W, N)
        hear = self._hear_key.index_select(0, (code >> 1).view(-1)).view(W, N, 1)
        rows = (_others(send) - hear).view(-1)
        slot = self._heard_slot.index_select(0, rows).view(W, N, N - 1, 4)
        extra = [*([] if energy is None else [_others(energy)])]
        if level is not None:
            extra.append((_others(level) - level.unsqueeze(-1)).unsqueeze(-1))
        if messages is not None:
            extra.append(_others(messages))
        if extra:  # zeros where not heard (the slot's fourth entry), as the slot's own
            unheard = slot[..., 3:] == 0
            slot = torch.cat([slot, *extra], -1)
            slot[..., 4:].masked_fill_(unheard, 0.0)
        parts.append(slot.flatten(-2))
        return torch.cat(parts, -1)

    def _node_slots(self, xyz: torch.Tensor, nodes: torch.Tensor) -> torch.Tensor:
        """``[*, 16]`` what UAVs at points ``xyz`` ``[*, 3]`` (cells, float64) hear of the nodes ``[*, 4, 3]``
        (broadcast): per node ``(dx / L1, dy / L2, dz / h, 1)`` within ``comm_radius``, zeros otherwise."""
        apart = nodes - xyz.unsqueeze(-2)  # [*, 4, 3]
        heard = apart.square().sum(-1) <= self.cfg.comm_radius_cells**2
        slot = torch.cat([apart / self._node_scale, torch.ones_like(apart[..., :1])], -1)
        return slot.where(heard.unsqueeze(-1), 0.0).flatten(-2).float()

    def energy_features(self, state: torch.Tensor) -> torch.Tensor | None:
        """``[..., N, 2]`` each UAV's battery and service flag as the ``state`` ``[..., S]`` shows them (what
        :meth:`configurations` takes); ``None`` without an energy model."""
        N = self.num_uavs
        return None if self.energy is None else state[..., 5 * N : 7 * N].unflatten(-1, (N, 2))

    def configurations(
        self,
        code: torch.Tensor,
        energy: torch.Tensor | None = None,
        nodes: torch.Tensor | None = None,
        messages: torch.Tensor | None = None,
    ) -> dict:
        """What an agent acts and learns from (``observation``, ``action_mask``, ``state``, ``positions``, ``tasks``)
        of ``W`` configurations given by their codes ``[W, N]`` (``2 cell + task``), under an energy model their
        features ``[W, N, 2]`` (:meth:`energy_features`), with ``layout=random`` their layouts' nodes ``[W, 4, 3]``,
        with ``message_size`` the messages ``[W, N, message_size]`` their UAVs received:
        what :meth:`reset` and :meth:`step` returned for them, bit for bit.  For a replay buffer that keeps
        configurations rather than observations.

        Example:
            >>> from uavrl.envs import World, make_config
            >>> world = World(make_config("paper", grid=(4, 4), num_uavs=3), batch_size=2)
            >>> out = world.reset()
            >>> again = world.configurations(world.code)
            >>> all(torch.equal(out[key], again[key]) for key in again)
            True
        """
        if (
            (self.energy is None) != (energy is None)
            or (self.layouts.fixed is None) == (nodes is None)
            or (self._s.messages is None) != (messages is None)
        ):
            raise ValueError(
                "World.configurations takes energy features exactly under an energy model (env.energy other than "
                "none), nodes exactly with env.layout=random and messages exactly with env.message_size above 0"
            )
        tables = None
        if nodes is not None:
            tables = self._observation_tables(
                relay_contributions(link_gains(self._cell_xyz, nodes, self.cfg), self.cfg), nodes
            )
        observation, state = self._assemble(code, energy, tables, messages)
        return self._outputs(observation, state, code >> 1, code & 1)

    def _outputs(self, observation, state, cell: torch.Tensor, task: torch.Tensor) -> dict:
        """The outputs an agent acts from, of configurations ``cell``, ``task`` ``[W, N]`` (their observation and
        state assembled)."""
        W, N = cell.shape
        out = {
            "observation": observation,
            "action_mask": self.dynamics.masks(cell),
            "state": state,
            "positions": self._cell_xy.index_select(0, cell.view(-1)).view(W, N, 2),
            "tasks": task,
        }
        if self._code_level is not None:  # with altitude levels, each UAV's level (0 the lowest)
            out["levels"] = self._slot_level.index_select(0, cell.view(-1)).view(W, N)
        return out

    def _observe(self, code: torch.Tensor, cell: torch.Tensor, task: torch.Tensor, moves, switches) -> dict:
        """The outputs of the configurations ``cell``, ``task`` ``[B, N]`` (``code`` their codes) after a step;
        ``moves()`` and ``switches()`` count the step's moves and task switches ``[B]`` (called for the diagnostics
        only)."""
        B, N = self.num_worlds, self.num_uavs
        if self._pair_obs is not None:
            pair = torch.add(code.flip(-1), code, alpha=2 * self.num_positions)  # [B, 2]: rows (a, b) and (b, a)
            observation = self._pair_obs.index_select(0, pair.view(-1)).view(B, N, -1)
            state = self._pair_state.index_select(0, pair[:, 0])
        else:
            observation, state = self._assemble(code)
        out = self._outputs(observation, state, cell, task.clone())  # the state's own tensor stays the World's
        if self._s.cancelled is not None:  # each UAV's own: was its move cancelled (docs/model.md, Local observations)
            out["cancelled"] = self._s.cancelled
        if not self.diagnostics:
            return out
        r = self._s.r.float()
        out.update(r_pu=r[:, 0], r_se=r[:, 1], utility=r[:, 0] + r[:, 1], moves=moves(), task_switches=switches())
        if self._state_base is not None:
            digits = code if self.cfg.state_includes_tasks else cell
            index = digits[:, N - 1]
            for i in range(N - 2, -1, -1):  # Horner: d_0 + base (d_1 + base (...)); sums over tiny dims are slow
                index = torch.add(digits[:, i], index, alpha=self._state_base)
            out["state_index"] = index.clone() if N == 1 else index
        return out
