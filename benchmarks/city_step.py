"""What a city of buildings costs the environment: a step, a reset and the first World of ``a2g_urban`` in an ITU-R
P.1410 city beside the same of the flat model, measured alternately in one process (docs/model.md, Cities of
buildings).

Models: ``a2g_urban`` (the flat model: no city, Al-Hourani urban), the same in the urban city (``env.city=urban``),
in the dense-urban one (``env.city=dense_urban env.environment=dense_urban``) and in the urban city with
``city_urban_10x10``'s five altitude levels (``env.altitudes_m=[30,60,100,200,300]``); layouts ``line`` (fixed: the
per-cell tables are built once, with the World) and ``random`` (each reset draws the reset worlds' layouts and
recomputes their tables, in a city their geometric line of sight); and, for the steps, the flat model with those five
levels (what the levels cost without a city).  ``B`` worlds (``--worlds``), N = 6, 10x10 cells
of 50 m, UAVs at 100 m, one torch thread, wall-clock milliseconds:

* ``step``: one ``env.step(td)`` of all ``B`` worlds (a masked uniform random action, drawn outside the timing);
* ``step + resets``: that step and then ``env.reset`` of ``B / T`` of the worlds (``T = 100``, ``a2g_urban``'s
  episode length; a different slice each step), what a step costs when the worlds' episodes are staggered;
* ``reset (all B)``: one ``env.reset()`` of every world.

Each figure is the median over ``--rounds`` rounds (a round: ``--steps`` steps, their mean, of each model and
layout in turn, after one warm-up round), so a load that changes during the run shifts every model alike.

``first World``: ``UAVSpectrumEnv(batch_size=B, config=cfg)`` for a city seed not built before in the process
(the city, generated once per model, and the line layout's tables), and ``city alone``: the city part of another
new seed (``envs/physics/buildings.py``'s ``city_part``), on the grids ``--grids``; median of ``--builds``.

Usage::

    python benchmarks/city_step.py | tee benchmarks/results/city_step.txt
    python benchmarks/city_step.py --worlds 1024 --rounds 3
"""

from __future__ import annotations

import argparse
import gc
import itertools
import os
import statistics
import time

import torch
from tensordict import TensorDict
from torchrl.envs.utils import step_mdp

from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.physics.buildings import city_part

MODELS = {
    "flat (no city)": {},
    "urban city": {"city": "urban"},
    "dense_urban city": {"city": "dense_urban", "environment": "dense_urban"},
    "urban city, 5 levels": {"city": "urban", "altitudes_m": [30, 60, 100, 200, 300]},  # city_urban_10x10's model
}
LEVELS_ONLY = {"flat (no city), 5 levels": {"altitudes_m": [30, 60, 100, 200, 300]}}  # the levels' own cost: steps only
LAYOUTS = ("line", "random")
FLAT = "flat (no city)"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--worlds", type=int, default=4096, help="worlds B (default 4096)")
    p.add_argument("--steps", type=int, default=20, help="timed steps per round (default 20)")
    p.add_argument("--rounds", type=int, default=7, help="alternating rounds; each figure is their median")
    p.add_argument("--grids", type=int, nargs="+", default=[10, 20], help="square grids of the first-World figures")
    p.add_argument("--builds", type=int, default=3, help="first Worlds per model and grid (new city seeds)")
    return p.parse_args(argv)


class Probe:
    """One model and layout's environment, stepped with a masked random policy and timed."""

    def __init__(self, overrides: dict, layout: str, worlds: int):
        self.horizon = make_config("a2g_urban").max_steps  # the episode length whose staggered resets are timed
        cfg = make_config("a2g_urban", layout=layout, max_steps=10**9, **overrides)  # no world truncates
        self.env = UAVSpectrumEnv(batch_size=worlds, config=cfg)
        self.worlds = worlds
        self.generator = torch.Generator().manual_seed(0)
        self.td = self.env.reset()
        self.slices = itertools.cycle(range(0, worlds, max(1, worlds // self.horizon)))

    def _act(self) -> None:
        mask = self.td.get(("agents", "action_mask"))
        action = torch.rand(mask.shape, generator=self.generator).masked_fill_(~mask, -1.0).argmax(-1)
        self.td.set(("agents", "action"), action)

    def step(self, resets: bool) -> float:
        """Seconds of one step of every world (and a reset of ``B / T`` of them)."""
        self._act()
        start = time.perf_counter()
        out = self.env.step(self.td)
        if resets:
            first = next(self.slices)
            mask = torch.zeros(self.worlds, dtype=torch.bool)
            mask[first : first + max(1, self.worlds // self.horizon)] = True
            self.td = self.env.reset(TensorDict({"_reset": mask}, batch_size=[self.worlds]))
        elapsed = time.perf_counter() - start
        if not resets:
            self.td = step_mdp(out)
        return elapsed

    def reset(self) -> float:
        start = time.perf_counter()
        self.td = self.env.reset()
        return time.perf_counter() - start


def step_table(args) -> None:
    models = MODELS | LEVELS_ONLY
    probes = {(m, layout): Probe(kw, layout, args.worlds) for m, kw in models.items() for layout in LAYOUTS}
    figures = {key: {"step": [], "step + resets": [], "reset (all B)": []} for key in probes}
    for round_ in range(args.rounds + 1):  # round 0 warms up
        for key, probe in probes.items():
            step = statistics.mean(probe.step(False) for _ in range(args.steps))
            resets = statistics.mean(probe.step(True) for _ in range(args.steps))
            reset = probe.reset()
            if round_:
                for name, value in zip(figures[key], (step, resets, reset), strict=True):
                    figures[key][name].append(value)
    T = probes[FLAT, "line"].horizon
    print(
        f"\nB = {args.worlds}, N = 6, 10x10: milliseconds, median of {args.rounds} rounds ({args.steps} steps each); "
        f"'step + resets': a step and a reset of B/{T} = {max(1, args.worlds // T)} worlds"
    )
    print("| model | layout | step (ms) | ratio to flat | step + resets (ms) | ratio | reset (all B) (ms) | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for (model, layout), measured in figures.items():
        row = f"| {model} | {layout} |"
        for name, values in measured.items():
            value, flat = statistics.median(values), statistics.median(figures[FLAT, layout][name])
            row += f" {1e3 * value:.2f} | {value / flat:.2f}x |"
        print(row, flush=True)


def build_table(args) -> None:
    seeds = itertools.count(1000)  # cities no probe has built
    print(
        f"\nThe first World: UAVSpectrumEnv(batch_size={args.worlds}, layout=line) of a new city seed (the city and "
        f"the layout's tables), and the city part alone; milliseconds, median of {args.builds}"
    )
    print("| grid | model | buildings | city alone (ms) | first World (ms) | ratio to flat |")
    print("|---|---|---|---|---|---|")
    for side in args.grids:
        base = None
        for model, overrides in MODELS.items():
            worlds, cities, buildings = [], [], 0
            for _ in range(args.builds + 1):  # the first warms up this grid's code paths
                city = {"city_seed": next(seeds)} if overrides else {}
                cfg = make_config("a2g_urban", grid=(side, side), layout="line", **overrides, **city)
                gc.collect()
                start = time.perf_counter()
                env = UAVSpectrumEnv(batch_size=args.worlds, config=cfg)
                worlds.append(time.perf_counter() - start)
                del env
                if overrides:
                    other = make_config(
                        "a2g_urban", grid=(side, side), layout="line", **overrides, city_seed=next(seeds)
                    )
                    start = time.perf_counter()
                    buildings = len(city_part(other).city.height)
                    cities.append(time.perf_counter() - start)
            world = statistics.median(worlds[1:])
            base = base or world
            alone = f"{1e3 * statistics.median(cities[1:]):.1f}" if cities else "-"
            print(
                f"| {side}x{side} | {model} | {buildings or '-'} | {alone} | {1e3 * world:.1f} | {world / base:.2f}x |",
                flush=True,
            )


def main(argv=None) -> None:
    args = parse_args(argv)
    torch.set_num_threads(1)
    began = time.perf_counter()
    print(
        f"# {time.strftime('%Y-%m-%d')}, torch {torch.__version__}, threads {torch.get_num_threads()}, "
        f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the start"
    )
    step_table(args)
    build_table(args)
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end; {time.perf_counter() - began:.0f} s")


if __name__ == "__main__":
    main()
