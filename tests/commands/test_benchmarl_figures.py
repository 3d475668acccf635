"""benchmarks/benchmarl_comparison.py's figures (docs/figures/benchmarl_*.png): every point inside its axes, one
legend for the figure, nothing cut at its edges."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def comparison():
    spec = importlib.util.spec_from_file_location("benchmarl_comparison", ROOT / "benchmarks/benchmarl_comparison.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def curve(scores, key, reach=0.5):
    return [
        {key: s, "eval/reach_999": reach, "eval/steps_to_999": 6.0, "time/train_cpu_seconds": 15.0 * (k + 1)}
        for k, s in enumerate(scores)
    ]


@pytest.mark.parametrize(
    "task, key, benchmarl_scores",
    [("n6_10x10", "eval/return", [-30.0, -2.5, 0.1, 0.25]), ("paper_6x6", "eval/return_ratio", [-0.6, 0.2, 0.9])],
)
def test_every_point_is_inside_its_axes_with_one_legend(tmp_path, monkeypatch, task, key, benchmarl_scores):
    """BenchMARL's early evaluations far below (they were cut at -1 and -0.1) and the DQN near the top, both shown."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    saved = []
    save = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **k: (saved.append(self), save(self, *a, **k))[1])
    results = {
        ("qmix", 0): {"curve": curve(benchmarl_scores, key, reach=0.0)},
        ("dqn", 0): {"curve": curve([0.3, 0.38, 0.39], key)},
        **{(row, 0): {"curve": curve([0.1, 0.2, 0.3], key, reach=0.0)} for row in ("vdn", "iql", "mappo")},
        ("dqn-qmix", 0): {"curve": curve([0.3, 0.38, 0.39], key)},
    }
    comparison().plot(task, results, tmp_path / f"benchmarl_{task}.png", 200)
    (figure,) = saved
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(figure).draw()  # pyplot let go of it when saved
    for ax in figure.axes:
        low, high = sorted(ax.get_ylim())
        values = [y for line in ax.get_lines() for y in line.get_ydata()]
        assert values and all(low < y < high for y in values)
    labels = [
        "BenchMARL qmix",
        "ours: DQN, VDN",
        "BenchMARL vdn",
        "BenchMARL iql",
        "BenchMARL mappo",
        "ours: DQN, QMIX",
    ]
    assert [t.get_text() for t in figure.legends[0].get_texts()] == labels
    assert figure.get_suptitle().endswith("seed 0 (200 held-out starts)")
    drawn, frame = figure.get_tightbbox(figure.canvas.get_renderer()), figure.bbox_inches
    assert drawn.x0 >= -0.01 and drawn.y0 >= -0.01 and drawn.x1 <= frame.x1 + 0.01 and drawn.y1 <= frame.y1 + 0.01
    legend = figure.legends[0].get_window_extent()
    assert not any(legend.overlaps(ax.get_window_extent()) for ax in figure.axes)
