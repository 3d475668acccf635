"""The benchmark's files held to the house standard: every file read through the guarded reader (no FIFO, device,
huge or sparse file, no link out of its directory), results files and cache entries read as untrusted input, and the
outputs (``out=``, ``save``, the leaderboard's page and figures, the cache) written only where the benchmark owns the
name, checked before any work.  Every refusal is one line naming the file as it was given; no file of a user's
changes."""

from __future__ import annotations

import copy
import json
import os
import signal
from pathlib import Path

import pytest

from uavrl.bench import cache, leaderboard
from uavrl.bench.results import PARTIAL, check_out, read, save
from uavrl.bench.tasks import SUITES
from uavrl.experiment.io import quoted, read_regular_text

STARTS = SUITES["tiny"][0].num_starts


@pytest.fixture(autouse=True)
def no_hang():
    """A reader that blocks on a FIFO fails the test after 20 s instead of hanging it."""

    def hung(*_):
        raise TimeoutError("a reader blocked")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(20)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def results_of(name: str = "mine", shift: float = 0.0) -> dict:
    """A results file of the tiny suite as score_suite writes it, without scoring (its scores made up)."""
    from uavrl.bench.results import new_results
    from uavrl.bench.stats import aggregate

    results = new_results("tiny", name, {"env_steps": 10}, "python")
    for k, task in enumerate(SUITES["tiny"]):
        scores = [[0.01 * ((s * 7 + k) % 90) + shift for s in range(STARTS)]]
        results["tasks"].append(
            {
                "task": task.name,
                "spec": task.spec(),
                "horizon": 20,
                "references": {
                    "value": "J",
                    "reference": {"kind": "exact", "values": [1.0] * STARTS},
                    "random": [0.0] * STARTS,
                    "planner": "oracle",
                    "planner_summary": {"eval/optimality": 1.0},
                    "u_star": [2.0] * STARTS,
                    "u_star_gap": 0.0,
                    "min_steps": [[3, 4]] * STARTS,
                    "min_steps_levels": ["0.99", "0.999"],
                    "min_steps_exact": True,
                },
                "status": "scored",
                "values": scores,
                "scores": scores,
                "mean_score": sum(scores[0]) / STARTS,
                "summary": {"eval/optimality": 0.9, "eval/reach_999": 0.5},
            }
        )
    pytest.importorskip("rliable")  # the aggregate: the tests of a whole results file run where [bench] is (.ci/docs)
    results["aggregate"] = aggregate(results, reps=50)
    return results


@pytest.fixture(scope="module")
def good() -> dict:
    return results_of()


def written(path: Path, results: dict) -> Path:
    path.write_text(json.dumps(results))
    return path


def one_line(err) -> str:
    message = str(err.value)
    assert "\n" not in message and "Traceback" not in message, message
    return message


def hostile(path: Path, kind: str) -> Path:
    """``path`` made a FIFO, a link to /dev/zero, a 20 GB sparse file, a directory or a link out of its folder."""
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "zero":
        path.symlink_to("/dev/zero")
    elif kind == "sparse":
        with open(path, "wb") as file:
            file.truncate(20 * 2**30)
    elif kind == "directory":
        path.mkdir()
    elif kind == "outside":
        outside = path.parent.parent / f"outside-{path.name}"
        outside.write_text("{}")
        path.symlink_to(outside)
    return path


HOSTILE = {
    "fifo": "is a FIFO, not a regular file",
    "zero": "is a character device, not a regular file",
    "sparse": "holds 21,474,836,480 bytes, more than uavrl writes there (16,777,216)",
    "directory": "is a directory, not a regular file",
}


# the guarded reader


@pytest.mark.parametrize("kind", HOSTILE)
def test_the_guarded_reader_refuses_special_huge_and_sparse_files_unread(kind, tmp_path):
    path = hostile(tmp_path / "file.json", kind)
    with pytest.raises(ValueError) as err:
        read_regular_text(path)
    assert one_line(err) == f"{path} {HOSTILE[kind]}"


def test_the_guarded_reader_refuses_a_link_out_of_its_directory(tmp_path):
    folder = tmp_path / "folder"
    folder.mkdir()
    link = hostile(folder / "entry.json", "outside")
    assert read_regular_text(link) == "{}"  # no directory given: the link is the user's to follow
    with pytest.raises(ValueError) as err:
        read_regular_text(link, within=folder)
    assert one_line(err) == f"{link} is a link to {tmp_path / 'outside-entry.json'}, out of {folder}"
    (folder / "inside.json").write_text("[]")
    (folder / "alias.json").symlink_to("inside.json")
    assert read_regular_text(folder / "alias.json", within=folder) == "[]"  # a link inside the folder is read


# results files


def test_every_committed_results_file_is_read():
    committed = sorted((Path(__file__).parents[2] / "benchmarks" / "results" / "leaderboard").glob("*.json"))
    assert len(committed) > 10 and all(read(path)["format"] == "uavrl-bench-results" for path in committed)


def _set(results: dict, where: str, value) -> dict:
    """``results`` with the field at ``where`` (``tasks.0.mean_score``) set to ``value`` (``...`` removes it)."""
    changed = copy.deepcopy(results)
    *parents, last = [int(part) if part.isdigit() else part for part in where.split(".")]
    holder = changed
    for part in parents:
        holder = holder[part]
    if value is ...:
        del holder[last]
    else:
        holder[last] = value
    return changed


MALFORMED = [
    ("suite", ..., "suite is missing"),
    ("suite", "nope", f'suite="nope" is invalid: allowed suites are {", ".join(map(repr, SUITES))}'),
    ("suite", "paper", 'tasks[0].task="tiny_3x3" is invalid: suite paper has paper_6x6, reference_code'),
    ("tasks.1.task", "tiny_3x3", 'tasks[1].task="tiny_3x3" is invalid: the task is given twice'),
    ("tasks.0.mean_score", "0.5", 'tasks[0].mean_score="0.5" is invalid: it must be a finite number'),
    ("tasks.0.mean_score", 0.123, "tasks[0].mean_score=0.123 is invalid: it is not its scores' mean"),
    ("tasks.0.scores", [[float("nan")] * STARTS], "tasks[0].scores=[[NaN, NaN"),
    ("aggregate.iqm", float("inf"), "aggregate.iqm=Infinity is invalid: it must be a finite number"),
    ("aggregate.iqm", {"x": 1}, "aggregate.iqm={...} is invalid: it must be a finite number"),
    ("aggregate.iqm", ..., "aggregate.iqm is missing"),
    ("aggregate.tasks", ["tiny_3x3"], 'aggregate.tasks=["tiny_3x3"] is invalid: the scored tasks are'),
    ("submission.name", ["a"], 'submission.name=["a"] is invalid: it must be one line of text'),
    ("environment.torch", "2.0\n# heading", 'environment.torch="2.0\\n# heading" is invalid: it must be one line'),
    ("submission.budget.env_steps", 2.7, "submission.budget.env_steps=2.7 is invalid: it must be a whole number"),
    ("submission.budget.steps", 5, "submission.budget.steps is invalid: no such field (allowed: env_steps"),
    ("tasks.0.spec.seed", 3, "tasks[0].spec is invalid: it is not task tiny_3x3's of this uavrl"),
    ("tasks.0.scores", [[0.5] * 3], "tasks[0].scores is invalid: one list of 32 scores per run"),
    ("tasks.0.references.random", [0.0], "tasks[0].references.random is invalid: it must hold 32 values"),
    ("tasks.0.summary", ..., "tasks[0].summary is missing (a task whose status is scored holds it)"),
    ("tasks", [], "tasks is invalid: a full protocol scores every task of suite tiny"),
    ("protocol", "whatever", 'protocol="whatever" is invalid: allowed values are \'full\', "partial'),
    ("tasks", "all", 'tasks="all" is invalid: it must be a list'),
]


@pytest.mark.parametrize("where, value, said", MALFORMED, ids=[f"{m[0]}={str(m[1])[:20]}" for m in MALFORMED])
def test_a_malformed_but_versioned_results_file_is_refused_naming_file_and_field(where, value, said, good, tmp_path):
    path = written(tmp_path / "r.json", _set(good, where, value))
    with pytest.raises(ValueError) as err:
        read(path)
    message = one_line(err)
    assert message.startswith(f"{path}: ") and said in message, message


@pytest.mark.parametrize(
    "text, said",
    [
        ('{"format": "uavrl-bench-results", "version": 1, "suite": ' + "[" * 100_000, "nests deeper than"),
        ("[" * 500 + "]" * 500, "not a uavrl benchmark results file"),
        ('{"format": "uavrl-bench-results", "version": "1"}', 'results version "1", this uavrl reads version 1'),
        ('{"format": "uavrl-bench-results", "version": true}', "results version true, this uavrl reads version 1"),
        ("{bad", "is not valid JSON (Expecting property name"),
    ],
)
def test_a_results_file_that_is_no_json_of_ours_is_refused(text, said, tmp_path):
    path = tmp_path / "r.json"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        read(path)
    assert said in one_line(err) and str(err.value).startswith(str(path))


def test_a_partial_results_file_is_read(good, tmp_path):
    partial = {**_set(good, "tasks", good["tasks"][:1]), "protocol": PARTIAL}
    partial["aggregate"] = {**good["aggregate"], "tasks": ["tiny_3x3"]}
    assert read(written(tmp_path / "p.json", partial))["protocol"] == PARTIAL


@pytest.mark.parametrize("kind", ["fifo", "zero", "sparse"])
def test_compare_refuses_a_special_file_in_one_line(kind, good, tmp_path, capsys):
    from uavrl.bench.__main__ import main

    path = hostile(tmp_path / "b.json", kind)
    with pytest.raises(ValueError) as err:
        main(["compare", str(written(tmp_path / "a.json", good)), str(path)])
    assert one_line(err).startswith(f"{path} {HOSTILE[kind]}")


# the references' cache


def payload() -> dict:
    """A cache entry's payload as compute_references writes it (two starts)."""
    tensor = {"dtype": "float64", "values": [1.0, 2.0]}
    baseline = {"values": [0.5, 1.5], "summary": {"eval/optimality": 0.5}}
    return {
        "starts": {
            "u_star": tensor,
            "u_start": tensor,
            "u_star_gap": 0.0,
            "best_return": None,
            "min_steps": {"dtype": "int64", "values": [[1, 2], [3, 4]]},
            "min_steps_levels": ["0.99", "0.999"],
            "exact": True,
        },
        "baselines": {"random": baseline, "oracle": baseline},
        "planner": "oracle",
        "reference": {"kind": "exact best return V*_H", "values": [1.0, 2.0]},
        "value": "discounted gain J",
        "horizon": 20,
        "cpu_seconds": 0.1,
    }


def resigned(path: Path, change) -> None:
    """The entry at ``path`` with its payload changed and its checksum recomputed, as anyone can."""
    entry = json.loads(path.read_text())
    change(entry["payload"])
    entry["sha256"] = cache._checksum(entry["payload"])
    path.write_text(json.dumps(entry))


def test_cache_keeps_json_and_recomputes_a_damaged_entry(tmp_path, capsys):
    calls = []

    def compute():
        calls.append(1)
        return payload()

    assert cache.cached(tmp_path, "k", compute) == payload()
    assert cache.cached(tmp_path, "k", compute) == payload() and len(calls) == 1
    path = tmp_path / "k.json"
    entry = json.loads(path.read_text())
    assert set(entry) == {"key", "sha256", "payload"}
    for damaged, said in (
        (json.dumps({**entry, "payload": {**payload(), "horizon": 21}}), "its payload does not match its checksum"),
        (json.dumps({**entry, "key": "other"}), "it is not the entry of its key"),
        (path.read_text()[:-7], "it is not JSON (Expecting"),  # cut short
        ("\x80\x04not json", "it is not JSON"),
        (b"\xff\xfe", "it is not UTF-8 text"),
    ):
        path.write_bytes(damaged if isinstance(damaged, bytes) else damaged.encode())
        before = len(calls)
        assert cache.cached(tmp_path, "k", compute) == payload() and len(calls) == before + 1
        assert said in capsys.readouterr().err
        assert cache.load(tmp_path, "k") == payload()  # rewritten whole


@pytest.mark.parametrize(
    "change, said",
    [
        (lambda p: p["starts"]["u_star"].update(dtype="load"), "payload.starts.u_star={...} is invalid: it must be"),
        (lambda p: p["reference"].update(values="1,2"), 'payload.reference.values="1,2" is invalid'),
        (lambda p: p["baselines"]["random"].update(values=[float("nan"), 0.0]), "payload.baselines.random.values="),
        (lambda p: p.pop("baselines"), "payload.baselines is missing"),
        (lambda p: p["baselines"].pop("oracle"), "payload.baselines.oracle is missing"),
        (lambda p: p["reference"].update(values=[1.0]), "payload.baselines.random.values is invalid: it must hold 1"),
        (lambda p: p.update(horizon=True), "payload.horizon=true is invalid: it must be a whole number >= 1"),
        (
            lambda p: p["reference"].update(values=[0.0, 0.0]),
            "payload.reference.values is invalid: the reference must beat the random policy on average",
        ),
    ],
)
def test_a_resigned_cache_entry_is_recomputed_with_one_warning(change, said, tmp_path, capsys):
    calls = []

    def compute():
        calls.append(1)
        return payload()

    cache.cached(tmp_path, "k", compute)
    resigned(tmp_path / "k.json", change)
    assert cache.cached(tmp_path, "k", compute) == payload() and len(calls) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"warning: the references' cache entry {tmp_path / 'k.json'} is damaged (") and said in err
    assert err.count("\n") == 1 and err.endswith("): recomputed and rewritten\n"), err
    assert cache.cached(tmp_path, "k", compute) == payload() and len(calls) == 2  # rewritten whole: read again
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("kind", ["fifo", "zero", "sparse", "outside"])
def test_a_special_or_linked_cache_entry_is_replaced_and_what_it_pointed_to_kept(kind, tmp_path, capsys):
    directory = tmp_path / "cache"
    directory.mkdir()
    entry = hostile(directory / "k.json", kind)
    assert cache.cached(directory, "k", payload) == payload()
    err = capsys.readouterr().err
    assert err.startswith(f"warning: the references' cache entry {entry} is damaged (it ") and err.count("\n") == 1
    assert entry.is_file() and not entry.is_symlink() and cache.load(directory, "k") == payload()
    if kind == "outside":
        assert (tmp_path / "outside-k.json").read_text() == "{}"


def refuse_to_compute(task):
    raise AssertionError("a reference was computed before the cache was checked")


def test_a_cache_dir_that_is_a_file_is_refused_before_any_reference(tmp_path, monkeypatch):
    from uavrl.bench import run

    monkeypatch.setattr(run, "compute_references", refuse_to_compute)
    mine = tmp_path / "mine.txt"
    mine.write_text("mine")
    for directory in (mine, mine / "cache"):
        with pytest.raises(NotADirectoryError) as err:
            run.score_suite("tiny", lambda env: None, name="x", cache_dir=directory)
        assert one_line(err) == f"cache_dir={directory} is invalid: {mine} is a file, not a directory"
    assert mine.read_text() == "mine"


def test_a_read_only_cache_dir_is_refused_before_any_reference(tmp_path, monkeypatch):
    from uavrl.bench import run
    from uavrl.bench.__main__ import parse

    monkeypatch.setattr(run, "compute_references", refuse_to_compute)
    directory = tmp_path / "cache"
    directory.mkdir()
    directory.chmod(0o555)
    if os.geteuid() == 0:  # root writes into a read-only directory: what the system says of it stands in
        real_access = cache.os.access
        monkeypatch.setattr(cache.os, "access", lambda path, mode: Path(path) != directory and real_access(path, mode))
    try:
        for given in (directory, directory / "sub"):
            with pytest.raises(PermissionError) as err:
                run.score_suite("tiny", lambda env: None, name="x", cache_dir=given)
            assert (
                one_line(err) == f"cache_dir={given} is invalid: {directory} is not writable: give a writable cache_dir"
            )
        with pytest.raises(PermissionError, match="^cache_dir=.* is not writable"):
            parse(["agent=random", f"cache_dir={directory}"])
    finally:
        directory.chmod(0o755)


def test_a_cache_dir_the_system_will_not_write_is_refused_before_any_reference(tmp_path, monkeypatch):
    """What a read-only mount says (os.access), for root too, whom a read-only mode does not stop."""
    from uavrl.bench import run

    monkeypatch.setattr(run, "compute_references", refuse_to_compute)
    monkeypatch.setattr(cache.os, "access", lambda path, mode: Path(path) != tmp_path)
    with pytest.raises(PermissionError) as err:
        run.score_suite("tiny", lambda env: None, name="x", cache_dir=tmp_path / "cache")
    assert (
        one_line(err)
        == f"cache_dir={tmp_path / 'cache'} is invalid: {tmp_path} is not writable: give a writable cache_dir"
    )


# outputs the benchmark owns


def test_save_never_replaces_a_users_table_or_figure(good, tmp_path):
    notes = tmp_path / "report.md"
    notes.write_text("my notes")
    with pytest.raises(FileExistsError) as err:
        save(good, tmp_path / "report.json")
    assert one_line(err).startswith(f"path={tmp_path / 'report.json'} is invalid: {notes} exists beside it")
    assert notes.read_text() == "my notes" and not (tmp_path / "report.json").exists()
    notes.unlink()
    written = save(good, tmp_path / "report.json")
    assert [path.name for path in written] == ["report.json", "report.md", "report.png"]
    save(results_of("again", shift=0.01), tmp_path / "report.json")  # its own files: replaced
    assert read(tmp_path / "report.json")["submission"]["name"] == "again"


@pytest.mark.parametrize(
    "name, content, said",
    [
        ("notes.md", "my notes", "is invalid: give a .json file (its table .md and figure .png go beside it)"),
        ("metrics.json", '{"eval/optimality": 0.5}', "is invalid: it exists and is no uavrl results file ("),
        ("thesis.json", None, "is invalid: it exists and is no uavrl results file ("),  # a directory
        ("fifo.json", "fifo", "is no uavrl results file (" + "{path} is a FIFO, not a regular file"),
        ("a.json", "png", "a.png exists beside it and the benchmark did not write it"),
    ],
)
def test_out_names_a_file_the_benchmark_does_not_own_refused_before_torch(name, content, said, tmp_path):
    from uavrl.bench.__main__ import parse

    path = tmp_path / name
    if content is None:
        path.mkdir()
    elif content == "fifo":
        os.mkfifo(path)
    elif content == "png":
        path.with_suffix(".png").write_text("my figure")
    else:
        path.write_text(content)
    before = {p: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    with pytest.raises((ValueError, OSError)) as err:
        parse(["agent=random", f"out={path}"])
    message = one_line(err)
    assert message.startswith(f"out={path} ") and said.format(path=path) in message, message
    assert {p: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before


def test_out_in_a_folder_that_cannot_be_made_is_refused(tmp_path):
    (tmp_path / "file").write_text("mine")
    with pytest.raises(NotADirectoryError) as err:
        check_out(tmp_path / "file" / "sub" / "r.json")
    assert (
        one_line(err)
        == f"out={tmp_path / 'file' / 'sub' / 'r.json'} is invalid: {tmp_path / 'file'} is a file, not a folder"
    )


def test_the_default_out_is_checked_before_any_scoring(tmp_path, monkeypatch):
    from uavrl.bench import scoring

    def score_suite(*args, **kwargs):
        raise AssertionError("scored before the out was checked")

    monkeypatch.setattr(scoring, "score_suite", score_suite)
    monkeypatch.chdir(tmp_path)
    figure = tmp_path / "bench" / "tiny" / "random.png"
    figure.parent.mkdir(parents=True)
    figure.write_text("my figure")
    with pytest.raises(FileExistsError) as err:
        scoring.score_command("tiny", {"agent": "random", "cache_dir": str(tmp_path / "cache")})
    assert one_line(err).startswith("out=bench/tiny/random.json is invalid: bench/tiny/random.png exists beside it")
    assert figure.read_text() == "my figure"


def test_the_run_costs_are_read_guarded(tmp_path):
    from uavrl.bench.scoring import run_costs

    assert run_costs(tmp_path) == {}
    (tmp_path / "metrics.json").write_text('{"train_cpu_seconds": 12}')
    assert run_costs(tmp_path) == {"cpu_seconds": 12.0}
    for text, said in (('{"train_cpu_seconds": "abc"}', "train_cpu_seconds='abc'"), ("fifo", "is a FIFO")):
        (tmp_path / "metrics.json").unlink()
        if text == "fifo":
            os.mkfifo(tmp_path / "metrics.json")
        else:
            (tmp_path / "metrics.json").write_text(text)
        with pytest.raises(ValueError) as err:
            run_costs(tmp_path)
        message = one_line(err)
        assert message.startswith(f"checkpoint={tmp_path}: cannot read the training's CPU seconds") and said in message
        assert message.endswith("give budget.cpu_seconds=<seconds>")


@pytest.mark.parametrize(
    "arg, said",
    [
        ("num_threads=5000", "num_threads=5000 is invalid: it must be a whole number in [1, 1024]"),
        ("num_threads=0", "num_threads=0 is invalid: it must be a whole number in [1, 1024]"),
        ("num_threads=" + "9" * 5000, "num_threads='999"),
        ("budget.env_steps=2.7", "budget.env_steps=2.7 is invalid: it must be a whole number >= 0"),
        ("name=a\nb", "name='a\\nb' is invalid: it must be one line of text"),
        ("name=", "name= is invalid: give a value (name=<...>)"),
        ("train_command=x\x00", "train_command='x\\x00' is invalid: it must be one line of text"),
    ],
)
def test_the_bench_settings_follow_the_commands_rules(arg, said):
    from uavrl.bench.__main__ import parse

    with pytest.raises(ValueError) as err:
        parse(["agent=random", arg])
    assert one_line(err).startswith(said)


# the leaderboard


@pytest.fixture
def results_dir(good, tmp_path) -> Path:
    folder = tmp_path / "results"
    folder.mkdir()
    written(folder / "mine.json", good)
    return folder


def test_the_leaderboard_regenerates_only_a_page_it_wrote(results_dir, tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# my notes\n\nno marker here\n")
    with pytest.raises(FileExistsError) as err:
        leaderboard.write(results_dir, page)
    assert one_line(err).startswith(f"out={page} is invalid: it exists without the line {leaderboard.MARKER}")
    assert page.read_text() == "# my notes\n\nno marker here\n"
    page.write_text(f"# kept\n\n{leaderboard.MARKER}\nold\n")
    leaderboard.write(results_dir, page)
    assert page.read_text().startswith(f"# kept\n\n{leaderboard.MARKER}\n") and "\nold\n" not in page.read_text()


@pytest.mark.parametrize("kind", ["fifo", "zero", "sparse", "directory"])
def test_the_leaderboard_reads_its_page_guarded(kind, results_dir, tmp_path):
    page = hostile(tmp_path / "page.md", kind)
    with pytest.raises(ValueError) as err:
        leaderboard.write(results_dir, page)
    assert one_line(err) == f"out={page} is invalid: {page} {HOSTILE[kind]}"


def test_a_new_page_never_replaces_a_users_figure(results_dir, tmp_path):
    figure = tmp_path / "figures" / "leaderboard-core.png"
    figure.parent.mkdir()
    figure.write_text("my figure")
    with pytest.raises(FileExistsError) as err:
        leaderboard.write(results_dir, tmp_path / "page.md")
    assert one_line(err).startswith(f"out={tmp_path / 'page.md'} is invalid: {figure} exists and the leaderboard did")
    assert figure.read_text() == "my figure" and not (tmp_path / "page.md").exists()


@pytest.mark.parametrize("kind", ["fifo", "zero", "sparse", "outside"])
def test_the_leaderboard_reads_its_results_guarded(kind, results_dir, tmp_path):
    entry = hostile(results_dir / "other.json", kind)
    page = tmp_path / "page.md"
    with pytest.raises(ValueError) as err:
        leaderboard.write(results_dir, page)
    outside = {"zero": "/dev/zero", "outside": tmp_path / "outside-other.json"}  # a link out: refused unread
    said = f"is a link to {outside[kind]}, out of {results_dir}" if kind in outside else HOSTILE[kind]
    assert one_line(err) == f"{entry} {said}" and not page.exists()


def test_the_leaderboard_needs_a_results_file_of_the_full_protocol(good, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    page = tmp_path / "page.md"
    with pytest.raises(ValueError) as err:
        leaderboard.write(empty, page)
    assert one_line(err) == (
        f"results={empty} is invalid: it holds no results file of the full protocol (none): a leaderboard ranks full "
        "runs of a suite"
    )
    partial = tmp_path / "partial"
    partial.mkdir()
    written(partial / "mine.json", {**good, "protocol": PARTIAL})
    with pytest.raises(ValueError, match=r"of the full protocol \(1 of partial protocol only\)"):
        leaderboard.write(partial, page)
    assert not page.exists()


@pytest.mark.parametrize("kind", ["file", "fifo", "missing"])
def test_the_leaderboard_results_must_be_a_directory(kind, tmp_path, capsys):
    from uavrl.bench.__main__ import main

    given = tmp_path / "results"
    if kind == "file":
        given.write_text("mine")
    elif kind == "fifo":
        os.mkfifo(given)
    with pytest.raises(OSError) as err:
        main(["leaderboard", f"results={given}", f"out={tmp_path / 'page.md'}"])
    words = {"file": "it is a file, not a directory", "fifo": "it is a FIFO, not a directory"}
    assert one_line(err) == f"results={given} is invalid: {words.get(kind, 'no such directory')}"


def test_a_foreign_out_is_refused_by_the_command_in_one_line(tmp_path):
    """Through ``python -m uavrl.bench``: one line on stderr, exit status 1, the user's notes as they were."""
    import subprocess
    import sys

    notes = tmp_path / "thesis.md"
    notes.write_text("my thesis")
    done = subprocess.run(
        [sys.executable, "-m", "uavrl.bench", "tiny", "agent=random", f"out={tmp_path / 'thesis.json'}"],
        capture_output=True,
        text=True,
    )
    out = tmp_path / "thesis.json"
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"error: out={quoted(out)} is invalid: {quoted(notes)} exists beside it")
    assert notes.read_text() == "my thesis" and not out.exists()


# load_experiment (the refusals come before BenchMARL is needed, so they are tested without it too)


def benchmarl_run(folder: Path, agent: str = "benchmarl_iql", task: str = "tiny_4x4") -> Path:
    """A directory holding what a finished python -m uavrl.benchmarl run holds, as far as its reader looks."""
    (folder / "iql_run" / "checkpoints").mkdir(parents=True)
    (folder / "metrics.json").write_text(json.dumps({"agent": agent}))
    (folder / "config.yaml").write_text(f"task:\n  name: {task}\n")
    (folder / "iql_run" / "checkpoints" / "checkpoint_2400.pt").write_bytes(b"PK")
    return folder


@pytest.mark.parametrize("given", [None, 3, b"runs/x", ["runs/x"]])
def test_load_experiment_of_no_path_is_a_type_error(given):
    from uavrl.experiment.benchmarl import load_experiment

    with pytest.raises(TypeError) as err:
        load_experiment(given)
    assert one_line(err) == f"run_dir={given!r} is invalid: give the run directory's path (a str or a pathlib.Path)"


def no_run(case: str, run: Path) -> Path:
    """The run directory ``run`` made into what ``case`` names (LOAD_REFUSALS); the path to give load_experiment."""
    if case == "missing":
        return run / "missing"
    if case in ("file", "fifo"):
        return hostile(run / "x", case) if case == "fifo" else (run / "x").write_text("x") and run / "x"
    if case == "empty":
        return run
    checkpoint = benchmarl_run(run, **LOAD_REFUSALS[case][1]) / "iql_run" / "checkpoints" / "checkpoint_2400.pt"
    if case in ("metrics fifo", "metrics zero", "metrics outside"):
        (run / "metrics.json").unlink()
        hostile(run / "metrics.json", case.split()[1])
    elif case == "checkpoint outside":
        checkpoint.unlink()
        (run.parent / "checkpoint_9.pt").write_bytes(b"PK")
        checkpoint.with_name("checkpoint_9.pt").symlink_to(run.parent / "checkpoint_9.pt")
    return run


LOAD_REFUSALS = {  # case: (what the refusal says, the run's metrics and config)
    "missing": ("run_dir={d}/missing is invalid: no such directory", {}),
    "file": ("run_dir={d}/x is invalid: it is a file, not a directory", {}),
    "fifo": ("run_dir={d}/x is invalid: it is a FIFO, not a directory", {}),
    "empty": ("run_dir={d} is no finished run of python -m uavrl.benchmarl: its metrics.json and config.yaml", {}),
    "metrics fifo": (
        "run_dir={d} is no finished run of python -m uavrl.benchmarl: its metrics.json and config.yaml "
        "cannot be read as the command writes them (metrics.json is a FIFO, not a regular file)",
        {},
    ),
    "metrics zero": ("them (metrics.json is a link to /dev/zero, out of {d})", {}),
    "metrics outside": ("them (metrics.json is a link to {d.parent}/outside-metrics.json, out of {d})", {}),
    "agent path": ("metrics.json's agent='benchmarl_../../x' names no", {"agent": "benchmarl_../../x"}),
    "task object": ("config.yaml's task.name={{'a': 1}} names no algorithm or task", {"task": "{a: 1}"}),
    "checkpoint outside": ("{d}/iql_run/checkpoints/checkpoint_9.pt is a link to", {}),
}


@pytest.mark.parametrize("case", LOAD_REFUSALS)
def test_load_experiment_refuses_what_is_no_run_in_one_line(case, tmp_path):
    from uavrl.experiment.benchmarl import load_experiment

    run = tmp_path / "run"
    run.mkdir()
    with pytest.raises(ValueError) as err:
        load_experiment(no_run(case, run))
    assert LOAD_REFUSALS[case][0].format(d=run) in one_line(err)


def test_load_experiment_without_benchmarl_says_how_to_install_it(tmp_path):
    import importlib.util

    from uavrl.experiment.benchmarl import load_experiment

    if importlib.util.find_spec("benchmarl") is not None:
        pytest.skip("BenchMARL is installed: tests/agents/test_benchmarl.py loads real runs")
    with pytest.raises(ImportError) as err:
        load_experiment(benchmarl_run(tmp_path))
    assert one_line(err).endswith(
        'needs BenchMARL, which is not installed: pip install torch==2.13.0 -e ".[benchmarl]"'
    )
