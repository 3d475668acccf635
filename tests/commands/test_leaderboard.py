"""The benchmark's pages and statistics: what markdown() and the leaderboard write (exact rows, every string of a
results file escaped, hostile names tried), the committed leaderboard regenerated, the floor of the normalised scores,
the results reader's refusals, and every aggregate and profile of uavrl.bench.stats against rliable's own functions.

The Markdown is parsed with MyST's parser configured as docs/conf.py configures it (markdown-it-py, installed with the
docs extra) where it is installed, else with markdown-it-py alone; the structural checks of the escaped text run
everywhere.  The rliable comparisons need the bench extra: CI's docs leg (.ci/docs) runs this file with both.
"""

import ast
import copy
import html
import json
import re
import unicodedata
from pathlib import Path

import numpy as np
import pytest

from uavrl.bench import leaderboard
from uavrl.bench.results import FORMAT, VERSION, markdown, markdown_text, read
from uavrl.bench.run import FLOOR, normalised

ROOT = Path(__file__).resolve().parents[2]
HOSTILE = [
    "</td><script>alert(1)</script>",
    "# heading",
    "name\n# heading\n\n| a | b |\n|---|---|",
    "[a link](https://example.invalid) ![an image](x.png) <https://example.invalid>",
    "`tick` and ``two`` and ```",
    "*em* **strong** _under_ ~~struck~~",
    "$x^2$ and $$y$$",
    "`code`{onclick=alert(1)} [x]{.class} {#id}",
    "a | b || c |",
    "back\\slash\\| and a trailing \\",
    "&lt;b&gt; &amp; &#60;script&#62;",
    "line\r\nbreak\u2028separator\x00nul\u202eright-to-left\tTab",
    ":::{note}\nadmonition\n:::",
    "<!-- an open comment",
    "1. item",
    "- item",
    "> quote",
    "{{ substitution }}",
    " padded `` ",
]


def visible(value: str) -> str:
    """What a page shows of ``value``: control and format characters as spaces, the ends trimmed (as a cell is)."""
    return "".join(" " if unicodedata.category(ch) in {"Cc", "Cf", "Cs", "Zl", "Zp"} else ch for ch in value).strip()


def hand_made(name="dqn (hand made)", source="python -m uavrl.bench paper checkpoint=runs/x", **environment) -> dict:
    """A small results file of suite ``paper``: paper_6x6 scored from 2 runs x 2 starts, reference_code n/a."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "suite": "paper",
        "protocol": "full",
        "submission": {
            "name": name,
            "source": source,
            "train_command": "python -m uavrl.train agent=dqn",
            "budget": {"env_steps": 1200, "cpu_seconds": 3.4},
        },
        "environment": {
            "uavrl": "0.2.0",
            "torch": "2.13.0",
            "torchrl": "0.14.1",
            "machine": "x86_64",
            "cpus": 2,
            "torch_threads": 1,
            **environment,
        },
        "tasks": [
            {
                "task": "paper_6x6",
                "status": "scored",
                "values": [[1.0, 2.0], [3.0, 6.0]],
                "scores": [[0.5, 0.75], [1.0, 0.25]],
                "mean_score": 0.625,
                "summary": {"eval/optimality": 0.9876, "eval/reach_999": 0.5, "eval/step_ratio_999": 1.234},
                "references": {"reference": {"kind": "exact best return V*_H"}, "min_steps_exact": True},
            },
            {
                "task": "reference_code",
                "status": "n/a",
                "reason": "acts in its own model only",
                "references": {"reference": {"kind": "the oracle planner"}, "min_steps_exact": False},
            },
        ],
        "aggregate": {
            "tasks": ["paper_6x6"],
            "rows": 4,
            "reps": 50,
            "confidence": 0.95,
            **{f"{m}": v for m, v in (("iqm", 0.625), ("mean", 0.625), ("median", 0.625), ("optimality_gap", 0.375))},
            **{f"{m}_ci": [0.25, 0.875] for m in ("iqm", "mean", "median", "optimality_gap")},
        },
    }


def test_markdown_writes_these_rows():
    assert markdown(hand_made()).splitlines() == [
        "| submission | suite | protocol | budget | command |",
        "|---|---|---|---|---|",
        "| dqn (hand made) | `paper` | full | 1,200 env steps, 3 CPU s | `python -m uavrl.bench paper "
        "checkpoint=runs/x` |",
        "",
        "| task | score (0 random, 1 reference) | reference | value | U / U* | reach 0.999 U* | steps / fewest |",
        "|---|---|---|---|---|---|---|",
        "| paper\\_6x6 | 0.625 | exact best return V\\*\\_H | 3 | 0.988 | 0.500 | 1.23 |",
        "| reference\\_code | n/a | the oracle planner | acts in its own model only | | | |",
        "",
        "Over 1 tasks x 4 starts: IQM 0.625 [0.250, 0.875], mean 0.625 [0.250, 0.875], median 0.625 [0.250, 0.875], "
        "optimality gap 0.375 [0.250, 0.875] (95% stratified bootstrap CIs, 50 replications, rliable).",
    ]


def test_the_leaderboard_table_writes_these_rows():
    second = hand_made(name="better")
    second["aggregate"]["iqm"] = 0.9
    assert leaderboard.suite_table("paper", [hand_made(), second]) == [
        "| submission | IQM [95% CI] | paper_6x6 | reference_code | budget | reproduce |",
        "|---|---|---|---|---|---|",
        "| better | 0.900 [0.250, 0.875] (1 of 2 tasks) | 0.625 | n/a | 1,200 env steps, 3 CPU s | "
        "`python -m uavrl.train agent=dqn`, then `python -m uavrl.bench paper checkpoint=runs/x` |",
        "| dqn (hand made) | 0.625 [0.250, 0.875] (1 of 2 tasks) | 0.625 | n/a | 1,200 env steps, 3 CPU s | "
        "`python -m uavrl.train agent=dqn`, then `python -m uavrl.bench paper checkpoint=runs/x` |",
    ]


# ----------------------------------------------------------------------------------- hostile strings, structurally
def unescaped(text: str) -> str:
    """The text a CommonMark reader takes from markdown_text's output: backslash escapes, then character references."""
    return html.unescape(re.sub(r"\\([!-/:-@\[-`{-~])", r"\1", text))


@pytest.mark.parametrize("value", HOSTILE)
def test_escaped_text_holds_no_markup(value):
    text = markdown_text(value)
    assert not re.search(r"[<>\x00-\x1f\x7f\u2028\u2029\u202e]", text)  # no tag, no line break, no control
    assert not re.search(r"&(?!lt;|gt;|amp;)", text)  # every & starts one of our three references
    # every character that starts markup comes escaped: after an odd run of backslashes
    for match in re.finditer(r"(\\*)([`*_\[\]{}#|$~])", text):
        assert len(match.group(1)) % 2 == 1, (value, text)
    assert unescaped(text).strip() == visible(value)


@pytest.mark.parametrize("value", HOSTILE)
def test_escaped_code_is_one_span(value):
    code = markdown_text(value, code=True)
    if not visible(value):
        assert code == ""
        return
    fence = re.match("`+", code).group()
    inner = code[len(fence) : -len(fence)]
    assert code.endswith(fence) and not inner.startswith("`") and not inner.endswith("`")
    assert all(len(run) != len(fence) for run in re.findall("`+", inner))  # no run closes the span early
    assert not re.search(r"[\x00-\x1f\x7f\u2028\u2029\u202e]", code)
    assert not re.search(r"(?<!\\)\|", inner)  # no pipe ends the table cell


# ------------------------------------------------------------------------------------ hostile strings, rendered
def docs_parser():
    """MyST's Markdown parser with docs/conf.py's extensions, else markdown-it-py's CommonMark with tables."""
    markdown_it = pytest.importorskip("markdown_it")
    try:
        from markdown_it.renderer import RendererHTML
        from myst_parser.config.main import MdParserConfig
        from myst_parser.parsers.mdit import create_md_parser
    except ImportError:
        return markdown_it.MarkdownIt("commonmark").enable("table")
    conf = (ROOT / "docs" / "conf.py").read_text()
    extensions = ast.literal_eval(re.search(r"^myst_enable_extensions = (\[.*?\])", conf, re.M | re.S).group(1))
    return create_md_parser(MdParserConfig(enable_extensions=set(extensions)), RendererHTML)


def flat(tokens):
    for token in tokens:
        yield token
        yield from flat(token.children or [])


def structure(tokens) -> list[str]:
    """The page's markup: every token but text."""
    return [t.type for t in flat(tokens) if t.type not in ("text", "text_special")]


def cells(tokens) -> list[str]:
    """Each table cell's visible text (its text and code)."""
    shown = ("text", "text_special", "code_inline")
    return [
        "".join(child.content for child in inline.children if child.type in shown)
        for cell, inline in zip(tokens, tokens[1:], strict=False)
        if cell.type in ("td_open", "th_open")
    ]


def hostile_file(value: str) -> dict:
    """A results file whose every string a page shows is ``value``."""
    results = hand_made(name=value, source=value, uavrl=value, machine=value)
    results["submission"]["train_command"] = results["tasks"][1]["reason"] = value
    results["tasks"][0]["references"]["reference"]["kind"] = value
    return results


@pytest.mark.parametrize("value", HOSTILE)
def test_a_hostile_string_makes_no_markup_in_the_pages(value):
    parser = docs_parser()
    plain = "plain words"
    for render in (lambda r: leaderboard.page([r], {}), markdown):
        benign, hostile = parser.parse(render(hostile_file(plain))), parser.parse(render(hostile_file(value)))
        # the same headings, tables, rows, cells, code spans and nothing else: no HTML, link, image, math, emphasis
        assert structure(hostile) == structure(benign), render(hostile_file(value))
        shown = cells(hostile)
        assert shown == [cell.replace(plain, visible(value)) for cell in cells(benign)]
        rendered = parser.render(render(hostile_file(value)))
        assert "<script" not in rendered and "<h1" not in rendered and "<a " not in rendered
    # the environment line: the version and machine strings shown as written
    paragraph = parser.parse(leaderboard.page([hostile_file(value)], {}))
    texts = ["".join(c.content for c in t.children) for t in paragraph if t.type == "inline" and "Scored" in t.content]
    assert texts and f"uavrl {visible(value)}, torch" in texts[0] and f" ({visible(value)}), " in texts[0]


def test_the_figures_take_hostile_names(tmp_path):
    from uavrl.bench.results import figure

    files = [hostile_file(value) for value in HOSTILE]
    figure(files, tmp_path / "hostile.png")  # mathtext, control characters, long names: drawn, not raised
    assert (tmp_path / "hostile.png").stat().st_size > 0


# ------------------------------------------------------------------------- the committed page, regenerated
@pytest.mark.parametrize(
    "results_file", sorted((ROOT / "benchmarks/results/leaderboard").glob("*.json")), ids=lambda p: p.stem
)
def test_each_committed_results_table_is_its_files(results_file):
    assert results_file.with_suffix(".md").read_text() == markdown(read(results_file))


def test_the_committed_leaderboard_is_regenerated_from_the_results_files(tmp_path):
    committed = (ROOT / "docs" / "leaderboard.md").read_text()
    out = tmp_path / "docs" / "leaderboard.md"
    out.parent.mkdir()
    out.write_text(committed.split(leaderboard.MARKER)[0] + leaderboard.MARKER + "\nstale\n")
    leaderboard.write(ROOT / "benchmarks/results/leaderboard", out)
    assert out.read_text() == committed, "regenerate: python -m uavrl.bench leaderboard"
    figures = sorted(path.name for path in (tmp_path / "docs" / "figures").iterdir())
    assert figures == sorted(re.findall(r"\(figures/(leaderboard-\w+\.png)\)", committed))


# ---------------------------------------------------------------------------------- scores and the reader
def test_normalised_scores_divide_a_start_near_the_reference_by_the_floor():
    random_values, reference_values = [0.0, 0.0, 9.9], [10.0, 10.0, 10.0]  # gaps 10, 10, 0.1: mean gap 6.7
    scores = normalised([5.0, 10.0, 10.0], random_values, reference_values)
    floor = FLOOR * (20.1 / 3)
    assert scores[:2] == [0.5, 1.0]
    assert scores[2] == pytest.approx(0.1 / floor) and scores[2] < 1  # not 0.1 / 0.1 = 1
    assert normalised([9.9], [9.9], [10.0]) == [0.0] and normalised([10.0], [9.9], [10.0]) == [1.0]  # one start
    with pytest.raises(ValueError, match="does not beat the random policy"):
        normalised([1.0, 1.0], [2.0, 1.0], [1.0, 2.0])  # mean gap 0


@pytest.mark.parametrize(
    "content",
    [
        "not json {",
        "[1, 2]",
        json.dumps({"format": "something else", "version": VERSION}),
        json.dumps({"format": FORMAT, "version": VERSION + 1}),
        json.dumps({"format": FORMAT}),
    ],
    ids=["not-json", "not-an-object", "other-format", "newer-version", "no-version"],
)
def test_the_reader_refuses_a_file_that_is_not_a_results_file(tmp_path, content):
    path = tmp_path / "results.json"
    path.write_text(content)
    with pytest.raises(ValueError) as refused:
        read(path)
    assert str(path) in str(refused.value) and "\n" not in str(refused.value)


def test_the_reader_refuses_a_missing_file(tmp_path):
    with pytest.raises(ValueError, match="absent.json"):
        read(tmp_path / "absent.json")


# ----------------------------------------------------------------------------- the statistics are rliable's
@pytest.fixture
def scores():
    """Normalised scores of 3 tasks x 12 rows, spread over [-0.3, 1.1] with ties, as a results file."""
    generator = np.random.default_rng(7)
    matrix = np.round(generator.uniform(-0.3, 1.1, size=(12, 3)), 1)
    tasks = [{"task": f"t{k}", "status": "scored", "scores": matrix[:, k].reshape(3, 4).tolist()} for k in range(3)] + [
        {"task": "t3", "status": "n/a"}
    ]
    return matrix, {"suite": "tiny", "tasks": tasks}


def test_every_aggregate_and_profile_is_rliables(scores):
    pytest.importorskip("rliable")
    from rliable import library, metrics

    from uavrl.bench.stats import BOOTSTRAP_SEED, METRICS, PROFILE_TAUS, aggregate

    matrix, results = scores
    reps = 200
    agg = aggregate(results, reps=reps)
    assert agg["tasks"] == ["t0", "t1", "t2"] and agg["rows"] == 12
    points = {
        "iqm": metrics.aggregate_iqm(matrix),
        "mean": metrics.aggregate_mean(matrix),
        "median": metrics.aggregate_median(matrix),
        "optimality_gap": metrics.aggregate_optimality_gap(matrix),
    }
    assert points["mean"] == pytest.approx(matrix.mean(axis=0).mean())  # rliable's mean: of the per-task means
    assert points["optimality_gap"] == pytest.approx(np.mean(1 - np.minimum(matrix, 1)))  # of every score
    for name in METRICS:
        assert agg[name] == points[name], name
        # the metric's CI from rliable's stratified bootstrap of that metric alone, numpy's generator seeded as stats
        state = np.random.get_state()
        np.random.seed(BOOTSTRAP_SEED)
        try:
            function = getattr(metrics, f"aggregate_{name}")
            _, interval = library.get_interval_estimates(
                {"x": matrix}, lambda x, f=function: np.array([f(x)]), reps=reps
            )
        finally:
            np.random.set_state(state)
        assert agg[f"{name}_ci"] == [interval["x"][0][0], interval["x"][1][0]], name
    assert agg["iqm_ci"] != agg["mean_ci"] and agg["median_ci"] != agg["optimality_gap_ci"]  # four different CIs
    # the performance profile: rliable's score distributions at the taus, with their own bootstrap CIs
    profile = agg["profile"]
    assert profile["taus"] == PROFILE_TAUS
    expected = library.score_distributions(matrix, PROFILE_TAUS)
    assert profile["fraction"] == [float(v) for v in expected]
    assert profile["fraction"][PROFILE_TAUS.index(0.5)] == pytest.approx(np.mean(matrix > 0.5))
    state = np.random.get_state()
    np.random.seed(BOOTSTRAP_SEED)
    try:
        _, band = library.get_interval_estimates(
            {"x": matrix}, lambda x: library.score_distributions(x, PROFILE_TAUS), reps=reps
        )
    finally:
        np.random.set_state(state)
    assert profile["ci_low"] == [float(v) for v in band["x"][0]]
    assert profile["ci_high"] == [float(v) for v in band["x"][1]]
    assert all(
        lo <= f <= hi for lo, f, hi in zip(profile["ci_low"], profile["fraction"], profile["ci_high"], strict=True)
    )


def test_the_aggregate_of_a_file_without_a_scored_task_is_empty(scores):
    from uavrl.bench.stats import aggregate

    _, results = scores
    nothing = copy.deepcopy(results)
    nothing["tasks"] = [{"task": "t3", "status": "n/a"}]
    assert aggregate(nothing) == {"tasks": [], "note": "no task of the suite could be scored"}
