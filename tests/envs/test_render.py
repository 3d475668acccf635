"""Rendering and videos: env.render() frames, TorchRL's PixelRenderTransform and VideoRecorder, the video command."""

import math
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest
import torch
from matplotlib.collections import PolyCollection
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from torchrl.envs import SerialEnv, TransformedEnv, check_env_specs
from torchrl.record import PixelRenderTransform, VideoRecorder
from torchrl.record.loggers import CSVLogger

from uavrl.cli import compose_config
from uavrl.envs import UAVSpectrumEnv, make_config
from uavrl.envs.physics.channel import PR, PT, cell_xyz
from uavrl.envs.physics.energy import CHARGING, WAITING
from uavrl.envs.render import (
    GAUGE_HEIGHT,
    GAUGE_LEVELS,
    GAUGE_TOP,
    GAUGE_WIDTH,
    IDLE_LINK,
    RELAY_COLOUR,
    SENSE_COLOUR,
    STATUS_COLOURS,
    WorldRenderer,
    render,
    tile,
)
from uavrl.envs.world import World
from uavrl.experiment.logger import RunLogger
from uavrl.experiment.rendering import render_checkpoint
from uavrl.experiment.video import can_write_mp4, comparison_frames, encode
from uavrl.render import as_overrides
from uavrl.train import train

TINY_RUN = ["env.grid=[3,3]", "agent.episodes=2", "env.max_steps=20", "agent.runs=1", "eval.num_starts=4"]


def colour_near(frame, row, col, colour, radius=3) -> bool:
    """Whether a pixel of exactly ``colour`` lies within ``radius`` of ``(row, col)`` (a disc's fill, not its digit)."""
    patch = frame[max(row - radius, 0) : row + radius + 1, max(col - radius, 0) : col + radius + 1]
    return bool((patch == np.array(colour, dtype=np.uint8)).all(-1).any())


def test_render_is_a_uint8_frame_of_the_chosen_world(tiny_env):
    env = UAVSpectrumEnv(batch_size=3, grid=(4, 4), num_uavs=2, layout="random", seed=5)
    env.reset()
    frames = [env.render(env_index=i) for i in range(3)]
    assert env.render_mode == "rgb_array"
    assert all(f.shape == (360, 480, 3) and f.dtype == np.uint8 for f in frames)
    assert not np.array_equal(frames[0], frames[1])  # another layout and other UAVs
    assert np.array_equal(env.render(mode="rgb_array", agent_index_focus=None), frames[0])  # TorchRL's examples' call
    assert np.array_equal(env.render(), frames[0])  # the same world drawn again is the same picture


def drawn_texts(renderer: WorldRenderer) -> list:
    """The texts a frame of ``renderer`` shows (the background's and the step's), with their pixels."""
    from matplotlib.text import Text

    return [t for t in renderer.figure.findobj(Text) if t.get_visible() and t.get_text()]


@pytest.mark.parametrize(
    "cfg",
    [
        make_config("paper", grid=(10, 10), num_uavs=6),
        make_config("paper", grid=(8, 5), num_uavs=3, layout="random"),
        make_config("paper", grid=(50, 50), num_uavs=6),
        make_config(
            "paper", grid=(10, 10), num_uavs=6, energy="rotary_wing", base=(-1, 0), num_spares=2, recharge_steps=9
        ),
    ],
    ids=["10x10", "random-8x5", "50x50", "energy-base-left"],
)
def test_a_frame_numbers_the_grid_cells_clear_of_the_nodes(cfg):
    """x under every column (or every 2nd, 5th, ... where cells are small) and y beside every row, each on its cell's
    line, none running into another or into a node or its name, none on the base's side of the grid."""
    world = World(cfg, batch_size=1, seed=3)
    world.reset()
    renderer = WorldRenderer(world)
    renderer.frame(0)
    L1, L2 = cfg.grid
    xs = [t for t in renderer._x_coordinates if t.get_visible()]
    ys = [t for t in renderer._y_coordinates if t.get_visible()]
    numbers = [[int(t.get_text()) for t in labels] for labels in (xs, ys)]
    every = min(b - a for shown in numbers for a, b in zip(shown, shown[1:], strict=False))
    assert all(n % every == 0 for shown in numbers for n in shown) and (every == 1 if max(L1, L2) <= 10 else every >= 2)
    assert all(t.get_position()[0] == int(t.get_text()) for t in xs)  # each under its column
    assert all(t.get_position()[1] == int(t.get_text()) for t in ys)  # each beside its row
    assert len(xs) >= -(-L1 // every) - 3 and len(ys) >= -(-L2 // every) - 3  # a few left out beside a node
    if cfg.energy != "none":  # the base's pad is left of the grid: y goes right of it
        assert all(t.get_position()[0] > L1 - 0.5 for t in ys)
    text_renderer = renderer.canvas.get_renderer()
    boxes = [t.get_window_extent(text_renderer) for t in [*xs, *ys]]
    assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1 :])
    names = [t.get_window_extent(text_renderer) for t in renderer._node_labels]
    assert not any(box.overlaps(name) for box in boxes for name in names)


def test_the_panel_has_a_key_and_names_its_share_column():
    world = World(make_config("paper", grid=(6, 6), num_uavs=3), batch_size=1, seed=0)
    world.reset()
    renderer = WorldRenderer(world)
    renderer.frame(0)
    texts = [t.get_text() for t in drawn_texts(renderer)]
    assert "UAV task  c/Σc" in texts and not any("share" in t for t in texts if t.startswith("UAV"))
    assert {"relay: PT → UAV → PR", "sense: S → UAV → E", "earns nothing", "c/Σc: its path's share"} <= set(texts)
    assert "away: status, steps left" not in texts  # the energy model's line


def test_uavs_show_in_their_task_colour_where_they_are():
    world = World(make_config("paper", grid=(6, 6), num_uavs=3), batch_size=2, seed=1)
    world.reset()
    renderer = WorldRenderer(world)
    for step in range(4):
        for index in range(2):
            frame = renderer.frame(index)
            code = world.code[index]
            for cell, task in zip((code >> 1).tolist(), (code & 1).tolist(), strict=True):
                x, y = cell % 6, cell // 6
                row, col = renderer.pixel_of(x, y)
                mine, other = (RELAY_COLOUR, SENSE_COLOUR) if task == 1 else (SENSE_COLOUR, RELAY_COLOUR)
                # off the centre, clear of the UAV's number
                assert colour_near(frame, row - 6, col, mine), (step, index, x, y, task)
                assert not colour_near(frame, row - 6, col, other, radius=1)
            # an empty cell holds neither colour
            empty = sorted(set(range(36)) - set((code >> 1).tolist()))[0]
            row, col = renderer.pixel_of(empty % 6, empty // 6)
            assert not colour_near(frame, row, col, RELAY_COLOUR, 2) and not colour_near(
                frame, row, col, SENSE_COLOUR, 2
            )
        world.step(torch.randint(0, 6, (2, 3)))


def rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)], dtype=np.uint8)


def gauge_pixels(frame, renderer, x, y) -> dict[str, int]:
    """The pixels of each gauge colour on the row through the middle of the gauge under the UAV at cell ``(x, y)``."""
    row, _ = renderer.pixel_of(x, y + GAUGE_TOP + GAUGE_HEIGHT / 2)
    _, left = renderer.pixel_of(x - 0.5, y)
    _, right = renderer.pixel_of(x + 0.5, y)
    line = frame[row, left:right]
    return {colour: int((line == rgb(colour)).all(-1).sum()) for _, colour in GAUGE_LEVELS}


def test_the_battery_gauge_is_as_long_as_the_battery_is_full_in_the_colour_of_its_level(hand_built):
    cfg = make_config("paper", grid=(6, 6), num_uavs=3, energy="follow_up", base=(-1, 0))
    capacity = cfg.step_energies.capacity
    cells = (7, 22, 27)
    world = hand_built(cfg, [2 * cell for cell in cells], [capacity, 0.45 * capacity, 0.1 * capacity])
    renderer = WorldRenderer(world, width=960, height=720)  # a gauge of about 37 pixels
    green, amber, red = (colour for _, colour in GAUGE_LEVELS)
    for battery in ((1.0, 0.45, 0.1), (0.75, 0.3, 0.05), (0.5, 0.2, 0.0)):
        world._s.battery = torch.tensor([battery], dtype=torch.float64) * capacity
        frame = renderer.frame(0)
        full = renderer.pixel_of(GAUGE_WIDTH, 0)[1] - renderer.pixel_of(0, 0)[1]  # the gauge's length in pixels
        for cell, fraction in zip(cells, battery, strict=True):
            drawn = gauge_pixels(frame, renderer, cell % 6, cell // 6)
            level = green if fraction >= 0.5 else amber if fraction >= 0.2 else red
            assert full > 30 and abs(drawn[level] - fraction * full) <= 1, (battery, cell, drawn, full)
            assert sum(drawn.values()) == drawn[level]  # one colour
    # the paper's model (no energy) draws no gauge
    plain = World(make_config("paper", grid=(6, 6), num_uavs=3), 1)
    plain.start_at(torch.tensor([[2 * cell for cell in cells]]))
    plain_renderer = WorldRenderer(plain)
    frame = plain_renderer.frame(0)
    assert all(sum(gauge_pixels(frame, plain_renderer, c % 6, c // 6).values()) == 0 for c in cells)


def test_a_uav_out_of_service_sits_at_the_base_in_its_status_colour():
    """UAV i waits i cells from the base along the grid's side: a spare from the start, a UAV sent home later."""
    cfg = make_config(
        "paper", grid=(6, 6), num_uavs=2, energy="follow_up", base=(-1, 0), recharge_steps=3, num_spares=1
    )
    world = World(cfg, 1, seed=0)
    world.reset()
    renderer = WorldRenderer(world)
    frame = renderer.frame(0)
    waiting, charging = rgb(STATUS_COLOURS[WAITING]), rgb(STATUS_COLOURS[CHARGING])
    row, col = renderer.pixel_of(-1, 2)  # the spare, UAV 2
    assert colour_near(frame, row - 5, col, waiting)
    assert renderer.pixel_of(-0.5, 0)[1] > col  # left of the grid
    uav_0 = int(world.code[0, 0]) >> 1
    x, y = uav_0 % 6, uav_0 // 6
    assert colour_near(frame, renderer.pixel_of(x, y)[0] - 5, renderer.pixel_of(x, y)[1], SENSE_COLOUR) or (
        colour_near(frame, renderer.pixel_of(x, y)[0] - 5, renderer.pixel_of(x, y)[1], RELAY_COLOUR)
    )
    # UAV 0 charging at the base: drawn at the base itself, gone from its cell
    world._s.cell[0, 0], world._s.status[0, 0] = cfg.num_cells, CHARGING
    frame = renderer.frame(0)
    row, col = renderer.pixel_of(-1, 0)
    assert colour_near(frame, row - 5, col, charging)
    row, col = renderer.pixel_of(x, y)
    assert not colour_near(frame, row - 5, col, SENSE_COLOUR, 2) and not colour_near(
        frame, row - 5, col, RELAY_COLOUR, 2
    )


@pytest.mark.parametrize("preset", ["paper", "reference_code"])
def test_links_that_earn_nothing_are_grey(preset):
    """All UAVs sensing: no lease, so no emergency rate (the authors' code: no rate at all); one relay pays; all
    relaying pays in the paper's model only."""
    world = World(make_config(preset, grid=(6, 6), num_uavs=2), batch_size=1)
    world.reset()
    renderer = WorldRenderer(world)
    idle = np.array([int(IDLE_LINK[i : i + 2], 16) for i in (1, 3, 5)], dtype=np.uint8)

    def grey_pixels(tasks):  # UAVs in cells 7 and 22; a few grey pixels come from anti-aliased text anyway
        world.start_at(torch.tensor([[2 * 7 + tasks[0], 2 * 22 + tasks[1]]]))
        return int((renderer.frame(0) == idle).all(-1).sum())

    assert grey_pixels((0, 0)) > 200 and grey_pixels((0, 1)) < 50
    assert (grey_pixels((1, 1)) > 200) == (preset == "reference_code")


def test_frames_change_with_the_step_and_not_otherwise():
    env = UAVSpectrumEnv(batch_size=1, grid=(5, 5), num_uavs=2, seed=0)
    env.reset()
    before = env.render()
    env.step(env.reset().set(("agents", "action"), torch.tensor([[3, 1]])))
    after = env.render()
    assert not np.array_equal(before, after)
    env.world.start_at(env.world.code.clone())
    assert not np.array_equal(env.render(), after)  # the step counter went back to 0
    assert np.array_equal(env.render(), env.render())


def test_a_list_of_worlds_is_tiled_and_a_focus_rings_a_uav(tiny_env):
    env = tiny_env(batch_size=4)
    env.reset()
    tiled = env.render(env_index=[0, 1, 2, 3])
    assert tiled.shape == (2 * 360 + 4, 2 * 480 + 4, 3)
    assert np.array_equal(tiled[:360, :480], env.render(env_index=0))
    assert np.array_equal(tiled[364:, 484:], env.render(env_index=3))
    assert np.array_equal(
        tile([env.render(env_index=i) for i in range(3)], columns=3)[:, 968:], env.render(env_index=2)
    )
    assert not np.array_equal(env.render(agent_index_focus=1), env.render())


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"mode": "human"}, "render(mode='human') is invalid: UAVSpectrumEnv renders mode='rgb_array' only"),
        ({"env_index": 2}, "render(env_index=2) is invalid: give a world 0..1 or a list of them"),
        ({"env_index": [0, -1]}, "render(env_index=[0, -1]) is invalid"),
        ({"env_index": True}, "render(env_index=True) is invalid"),
        ({"agent_index_focus": 2}, "render(agent_index_focus=2) is invalid: give a UAV 0..1, or None for none"),
    ],
)
def test_bad_render_arguments_are_one_line(tiny_env, kwargs, message):
    env = tiny_env()
    env.reset()
    with pytest.raises(ValueError) as refused:
        env.render(**kwargs)
    assert str(refused.value).startswith(message) and "\n" not in str(refused.value)


def test_render_before_reset_says_so(tiny_env):
    with pytest.raises(RuntimeError, match=r"render\(\) before any reset"):
        tiny_env().render()
    world = World(make_config("paper", grid=(3, 3)), 1)
    with pytest.raises(RuntimeError, match="call env.reset"):
        render(world)


def test_pixel_render_transform_and_video_recorder_write_a_video(tmp_path, tiny_env):
    """TorchRL's own recording path: the frames of a rollout through PixelRenderTransform, dumped by VideoRecorder."""
    logger = CSVLogger("rollout", log_dir=str(tmp_path), video_format="pt")
    env = TransformedEnv(tiny_env(batch_size=3, max_steps=5), PixelRenderTransform())
    check_env_specs(env)  # the frame's spec: non-tensor data, one picture for the batch (VMAS's way)
    env.append_transform(VideoRecorder(logger, "uavs", skip=1))  # every frame (0.11 kept every second)
    td = env.rollout(5)
    assert td.get(("next", "pixels")).batch_size == (3, 5)  # world 0's frame at every step, shared by the batch
    env.transform.dump()
    video = torch.load(tmp_path / "rollout" / "videos" / "uavs_0.pt")
    assert video.shape == (1, 6, 3, 360, 480) and video.dtype == torch.uint8  # the reset and 5 steps
    assert not torch.equal(video[0, 0], video[0, -1])


def add_world_dim(frame):
    return frame[None]


def one_world_with_pixels():
    env = UAVSpectrumEnv(batch_size=1, grid=(3, 3), num_uavs=2, max_steps=5)
    return TransformedEnv(env, PixelRenderTransform(preproc=add_world_dim))


def torchvision_is_broken() -> bool:
    """VideoRecorder tiles with torchvision where it is installed; BenchMARL's set brings PyPI's torchvision, built
    for another torch than the CPU build, whose operators then fail to load."""
    try:
        import torchvision  # noqa: F401
    except ImportError:
        return False
    except RuntimeError:
        return True
    return False


@pytest.mark.skipif(torchvision_is_broken(), reason="torchvision does not match the installed torch build")
def test_a_batched_env_records_its_workers_side_by_side(tmp_path):
    """Over SerialEnv (ParallelEnv alike): each worker's frame as a [1, H, W, 3] tensor, tiled by the outer
    VideoRecorder."""
    logger = CSVLogger("workers", log_dir=str(tmp_path), video_format="pt")
    env = TransformedEnv(SerialEnv(2, one_world_with_pixels), VideoRecorder(logger, "uavs"))
    assert env.rollout(3)["next", "pixels"].shape == (2, 1, 3, 360, 480, 3)
    env.transform.dump()
    env.close()
    assert torch.load(tmp_path / "workers" / "videos" / "uavs_0.pt").shape == (1, 4, 3, 360, 2 * 480)


def test_comparison_frames_are_the_policy_beside_the_oracle_from_the_evaluation_starts():
    from uavrl.agents.baselines import OraclePolicy
    from uavrl.agents.evaluation import EVAL_SEED

    cfg = make_config("paper", grid=(3, 3))
    frames = comparison_frames(OraclePolicy(cfg), cfg, starts=2, horizon=3, label="oracle")
    assert frames.shape == (4, 2 * 360 + 4, 2 * 480 + 4, 3)
    # the oracle on both sides: the same pictures
    assert np.array_equal(frames[:, :, :480], frames[:, :, 484:])
    # row 1 is the evaluation's second start (world 1 of a batch seeded EVAL_SEED)
    env = UAVSpectrumEnv(batch_size=2, config=cfg.replace(max_steps=3), seed=EVAL_SEED)
    env.reset()
    start = WorldRenderer(env.world, label="oracle").frame(1)
    assert np.array_equal(frames[0, 364:, :480], start)


def test_encoded_videos_read_back_with_every_frame():
    frames = np.stack([np.full((40, 60, 3), 20 * t, dtype=np.uint8) for t in range(5)])
    assert iio.imread(encode(frames, fps=4), index=None, extension=".gif").shape == (5, 40, 60, 3)
    if can_write_mp4():
        odd = frames[:, :39, :59]
        assert iio.imread(encode(odd, 4, ".mp4"), index=None, extension=".mp4").shape == (5, 40, 60, 3)


def test_tensorboard_gets_the_video_as_an_animated_gif(tmp_path):
    frames = np.stack([np.full((40, 60, 3), 30 * t, dtype=np.uint8) for t in range(3)])
    logger = RunLogger(tmp_path)
    logger.video("eval/video", frames, step=7, fps=2)
    logger.close()
    events = EventAccumulator(str(tmp_path), size_guidance={"images": 0}).Reload()
    (image,) = events.Images("eval/video")
    assert image.step == 7 and (image.height, image.width) == (40, 60)
    assert iio.imread(image.encoded_image_string, index=None, extension=".gif").shape == (3, 40, 60, 3)


def test_the_command_writes_a_readable_gif_of_a_run(tmp_path, compose_cfg):
    run_dir = train(compose_cfg(*TINY_RUN, "progress=false", f"run_dir={tmp_path / 'run'}"))
    overrides = as_overrides([str(run_dir), "eval.video_starts=2", "eval.horizon=3"])
    assert overrides[0] == f"checkpoint='{run_dir}'"
    written = render_checkpoint(compose_config("config", overrides))
    assert written == [run_dir / "video.gif", *([run_dir / "video.mp4"] if can_write_mp4() else [])]
    for path in written:  # the start and 3 steps; 2 starts, each the policy beside the oracle
        assert iio.imread(path, index=None).shape == (4, 2 * 360 + 4, 2 * 480 + 4, 3)


def test_a_bare_run_directory_is_the_checkpoint(tmp_path):
    sweep_job = tmp_path / "agent=dqn" / "seed=0"  # a sweep's run directory: "=" in its name
    sweep_job.mkdir(parents=True)
    args = [str(sweep_job), "eval.seed=3", "--help"]
    assert as_overrides(args) == [f"checkpoint='{sweep_job}'", "eval.seed=3", "--help"]
    for name in ("it's \\ here", "end\\", "quote\\'s"):
        path = str(tmp_path / name)
        assert compose_config("config", as_overrides([path])).checkpoint == path


@pytest.mark.slow
def test_the_command_line_prints_the_files_it_wrote(tmp_path, compose_cfg):
    run_dir = train(compose_cfg(*TINY_RUN, "progress=false", f"run_dir={tmp_path / 'run'}"))
    done = subprocess.run(
        [sys.executable, "-m", "uavrl.render", str(run_dir), "eval.video_starts=1", "eval.horizon=2"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    written = [run_dir / "video.gif", *([run_dir / "video.mp4"] if can_write_mp4() else [])]
    assert done.stdout.splitlines() == [str(path) for path in written]
    assert iio.imread(run_dir / "video.gif", index=None).shape == (3, 360, 2 * 480 + 4, 3)


def test_evaluate_with_video_writes_the_gif_and_tensorboard(tmp_path, compose_cfg):
    from uavrl.experiment.evaluating import evaluate_checkpoint

    run_dir = train(compose_cfg(*TINY_RUN, "progress=false", f"run_dir={tmp_path / 'run'}"))
    evaluate_checkpoint(
        compose_cfg(f"checkpoint={run_dir}", "eval.video=true", "eval.video_starts=1", "eval.horizon=2")
    )
    assert iio.imread(run_dir / "video.gif", index=None).shape == (3, 360, 2 * 480 + 4, 3)
    events = EventAccumulator(str(run_dir), size_guidance={"images": 0}).Reload()
    assert [image.step for image in events.Images("eval/video")] == [40]  # the run's 2 episodes of 20 steps


def test_training_logs_the_video_at_its_evaluations(tmp_path, compose_cfg):
    run_dir = train(
        compose_cfg(
            *TINY_RUN, "eval.every=1", "eval.video=true", "eval.video_starts=1", "eval.horizon=2", "progress=false",
            f"run_dir={tmp_path / 'run'}",
        )
    )  # fmt: skip
    events = EventAccumulator(str(run_dir), size_guidance={"images": 0}).Reload()
    videos = events.Images("eval/video")
    assert [image.step for image in videos] == [20, 40]  # after each of the 2 episodes
    assert iio.imread(videos[-1].encoded_image_string, index=None, extension=".gif").shape == (3, 360, 964, 3)


def test_a_bad_video_setting_is_one_line(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "uavrl.render", str(tmp_path), "eval.video_starts=0"], capture_output=True, text=True
    )
    assert done.returncode == 1
    assert done.stderr.strip() == "error: eval.video_starts=0 is invalid: it must be a whole number >= 1"


# ------------------------------------------------------------------ cities
def city_world(**overrides) -> World:
    world = World(make_config("a2g_urban", city="urban", city_seed=0, **overrides), batch_size=1)
    world.reset()
    return world


def clear_of_grid_lines(v: np.ndarray, margin: float = 0.15) -> np.ndarray:
    """Whether each coordinate ``v`` (cells) is at least ``margin`` from the grid's lines (at ``k - 0.5``)."""
    return np.abs((v + 0.5) - np.round(v + 0.5)) >= margin


def test_footprints_in_cells_are_the_buildings_where_the_model_finds_them():
    part = city_world().parts["city"]
    footprints = part.footprints_cells()
    x0, y0, x1, y1 = footprints.T
    assert footprints.shape == (len(part.city.x0), 4) and (x1 > x0).all() and (y1 > y0).all()
    halfway_up = part.city.height / 2 / part.cell_size
    centres = torch.from_numpy(np.stack([(x0 + x1) / 2, (y0 + y1) / 2, halfway_up], -1))
    assert part.inside(centres).all()
    beside = centres.clone()
    beside[:, 0] = torch.from_numpy(x1 + 0.02)  # a metre east of the east wall: in the street
    assert not part.inside(beside).any()


def test_a_city_frame_shows_the_buildings_shaded_by_height_and_the_streets_between():
    """All UAVs over cell (5, 5): the links run along y = 5, so the grid's other rows show only buildings and
    streets."""
    world = city_world()
    world.start_at(torch.tensor([[2 * 55 + t for t in (1, 0, 1, 0, 1, 0)]]))
    renderer = WorldRenderer(world, width=640, height=480)
    frame = renderer.frame(0)
    assert renderer.buildings in renderer.ax.collections
    x0, y0, x1, y1 = renderer.city.footprints_cells().T
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    free = (cx > 0) & (cx < 9) & (cy > 0) & (cy < 9) & (np.abs(cy - 5) > 1.5)
    shown = np.flatnonzero(free & clear_of_grid_lines(cx) & clear_of_grid_lines(cy))
    assert len(shown) >= 10
    expected = np.round(renderer.buildings.get_facecolors()[shown, :3] * 255)
    drawn = np.array([frame[renderer.pixel_of(cx[k], cy[k])] for k in shown], dtype=float)
    assert np.abs(drawn - expected).max() <= 1
    heights = renderer.city.city.height[shown]
    brightness = drawn.mean(-1)
    assert (np.diff(brightness[np.argsort(heights)]) <= 1).all()  # darker as taller
    assert brightness[heights.argmax()] < brightness[heights.argmin()] - 20
    # a street: no building within 0.15 cells
    xs, ys = np.meshgrid(np.linspace(0.1, 8.9, 89), np.linspace(0.1, 8.9, 89))
    xs, ys = xs.ravel(), ys.ravel()
    near = (
        (xs[:, None] > x0 - 0.15) & (xs[:, None] < x1 + 0.15) & (ys[:, None] > y0 - 0.15) & (ys[:, None] < y1 + 0.15)
    ).any(-1)
    street = np.flatnonzero(~near & clear_of_grid_lines(xs) & clear_of_grid_lines(ys) & (np.abs(ys - 5) > 1.5))
    assert len(street) >= 10
    assert all((frame[renderer.pixel_of(xs[k], ys[k])] == rgb("#f3f3f3")).all() for k in street)


def test_in_a_city_a_blocked_link_is_dashed_and_grey_still_means_it_earns_nothing(monkeypatch):
    world = city_world()
    part = world.parts["city"]
    clear = part.line_of_sight(cell_xyz(world.cfg), world.nodes[0]).numpy()  # [C, 4]
    blocked_pt = int(np.flatnonzero(~clear[:, PT] & clear[:, PR])[0])
    blocked_pr = int(np.flatnonzero(clear[:, PT] & ~clear[:, PR])[0])
    calls = []
    real = part.line_of_sight
    monkeypatch.setattr(part, "line_of_sight", lambda *a: calls.append(1) or real(*a))
    renderer = WorldRenderer(world)

    def links(code):  # each link's (dashed, grey)
        world.start_at(torch.tensor([code]))
        renderer.frame(0)
        dashed = [dashes is not None for _, dashes in renderer._links.get_linestyles()]
        grey = [tuple(np.round(c[:3] * 255)) == tuple(rgb(IDLE_LINK)) for c in renderer._links.get_colors()]
        return list(zip(dashed, grey, strict=True))

    relay, sense = 1, 0
    code = [2 * blocked_pt + relay, 2 * blocked_pr + relay, 2 * blocked_pt + sense, 0, 0, 0]
    blocked = [(True, False)]  # dashed, in the relay's colour
    assert links(code) == blocked + [(False, False)] * 2 + blocked + [(False, False)] * 8
    assert links([2 * blocked_pt + sense] * 6) == [(False, True)] * 12  # S and E: above the roofs; no relay: no lease
    assert len(calls) == 1  # once per layout
    texts = [t.get_text() for t in drawn_texts(renderer)]
    tallest = math.ceil(part.city.height.max())
    assert {"LoS", "NLoS: blocked", f"buildings 0–{tallest} m", "earns nothing"} <= set(texts)


@pytest.mark.parametrize("overrides", [{}, {"city": "urban", "los": "statistical"}], ids=["no-city", "statistical"])
def test_without_geometric_line_of_sight_links_are_as_before(overrides):
    """Outside a city no building is drawn and the dash means what it meant; a city of statistical line of sight
    draws its buildings but dashes no link for NLoS."""
    world = World(make_config("a2g_urban", **overrides), batch_size=1)
    world.reset()
    renderer = WorldRenderer(world)
    for code, dashed in (([1, 0, 0, 0, 0, 0], False), ([0] * 6, True)):  # one relay pays; none relaying: no lease
        world.start_at(torch.tensor([code]))
        renderer.frame(0)
        assert [d is not None for _, d in renderer._links.get_linestyles()] == [dashed] * 12
    texts = {t.get_text() for t in drawn_texts(renderer)}
    assert "LoS" not in texts and "NLoS: blocked" not in texts
    if not overrides:
        assert renderer.city is None and not hasattr(renderer, "buildings")
        assert not any(isinstance(c, PolyCollection) for c in renderer.ax.collections)
        assert not any(t.startswith("buildings") for t in texts)
    else:
        assert renderer.buildings in renderer.ax.collections
