"""Nothing a user owns is deleted or silently replaced, and no reader opens a special file.

``reproduce`` removes and overwrites only the files it recorded writing (``.uavrl-written.json``), ``evaluate``
writes an evaluation with other settings beside the earlier one, and FIFOs, devices and directories where a file is
read are refused in one line naming the file.
"""

from __future__ import annotations

import json
import os

import pytest

from uavrl.experiment.checkpoints import CheckpointError, load_checkpoint, read_torch
from uavrl.experiment.io import Manifest, read_regular_text, special_kind
from uavrl.reproduce import check_settings, reproduce

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

TINY = ["grids=[2]", "runs=1", "episodes=2", "eval_starts=4", "progress=false"]


@pytest.fixture
def reproduce_cfg(compose_cfg):
    return lambda *overrides: compose_cfg(*TINY, *overrides, config_name="reproduce")


@pytest.fixture
def users_run(tmp_path):
    """A folder of a user's: a training run's files, TensorBoard notes and a figure of their own."""
    run = tmp_path / "run"
    (run / "tensorboard").mkdir(parents=True)
    files = {
        "config.yaml": "seed: 0\n",
        "metrics.json": "{}\n",
        "events.out.tfevents.1.host.1.0": "events",
        "tensorboard/notes.txt": "my notes\n",
        "fig_mine.png": "a figure of mine",
        "fig9_extra.png": "another",
    }
    for name, text in files.items():
        (run / name).write_text(text)
    return run, files


def same_files(run, files) -> bool:
    return all((run / name).read_text() == text for name, text in files.items())


def test_reproduce_with_overwrite_removes_only_what_it_wrote(users_run, reproduce_cfg):
    run, files = users_run
    with pytest.raises(FileExistsError, match=r"^out_dir=.* holds results of unknown settings: give another out_dir"):
        check_settings(reproduce_cfg("command=table2", f"out_dir={run}"))  # its tensorboard/ and fig*.png
    reproduce(reproduce_cfg("command=table2", f"out_dir={run}", "overwrite=true"))
    assert same_files(run, files)
    written = set(json.loads((run / Manifest.NAME).read_text()))
    events = [p.relative_to(run).as_posix() for p in (run / "tensorboard" / "grid2x2").glob("events.out.tfevents.*")]
    assert written == {"variant.json", "table2.md", "table2.json", "history_2x2.pt", *events} and len(events) == 1
    # another variant over it: reproduce's own files of the first go, the user's stay (their folder too)
    reproduce(reproduce_cfg("command=table2", "grids=[3]", f"out_dir={run}", "overwrite=true"))
    assert same_files(run, files)
    assert not (run / "history_2x2.pt").exists() and not (run / "tensorboard" / "grid2x2").exists()
    assert (run / "history_3x3.pt").exists() and json.loads((run / "variant.json").read_text())["grids"] == [3]
    assert "history_2x2.pt" not in json.loads((run / Manifest.NAME).read_text())


def test_a_users_file_of_a_name_reproduce_writes_is_refused_before_any_work(users_run, reproduce_cfg):
    run, files = users_run
    (run / "fig3_sum_utility.png").write_text("mine")
    for overwrite in ("false", "true"):
        cfg = reproduce_cfg("command=figures", "figure_grid=2", f"out_dir={run}", f"overwrite={overwrite}")
        refusal = "holds results of unknown settings" if overwrite == "false" else "holds fig3_sum_utility.png, which"
        with pytest.raises(FileExistsError, match=refusal):
            check_settings(cfg)
    assert (run / "fig3_sum_utility.png").read_text() == "mine" and same_files(run, files)


def special(path, kind: str):
    """Make ``path`` a FIFO, a directory or a symbolic link to a character device."""
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    else:
        path.symlink_to("/dev/null")


SPECIAL = {"fifo": "a FIFO", "directory": "a directory", "device": "a character device"}


@pytest.mark.parametrize("overwrite", ["false", "true"])
@pytest.mark.parametrize(
    ("content", "said"),
    [
        ("[1, 2, 3]", "holds a JSON list: expected the JSON object of settings"),
        ('"paper"', "holds a JSON str"),
        ("{bad", "is not valid JSON (Expecting property name"),
        ("", "is not valid JSON"),
        (b"\xff\xfe", "is not UTF-8 text"),
        *((kind, f"is {words}, not a regular file") for kind, words in SPECIAL.items()),
    ],
)
def test_a_variant_json_that_reproduce_did_not_write_is_refused_in_one_line(
    content, said, overwrite, tmp_path, reproduce_cfg
):
    out = tmp_path / "out"
    out.mkdir()
    record = out / "variant.json"
    if content in SPECIAL:
        special(record, content)
    elif isinstance(content, bytes):
        record.write_bytes(content)
    else:
        record.write_text(content)
    with pytest.raises(ValueError) as err:
        check_settings(reproduce_cfg("command=table2", f"out_dir={out}", f"overwrite={overwrite}"))
    message = str(err.value)
    assert message.startswith(f"{record} ") and said in message and "\n" not in message, message


@pytest.mark.parametrize("kind", ["file", "fifo", "device"])
def test_reproduce_into_an_out_dir_that_is_no_folder_is_refused_before_any_work(kind, tmp_path, reproduce_cfg):
    out = tmp_path / "out"
    if kind == "file":
        out.write_text("mine")
    else:
        special(out, kind)
    words = {"file": "a file", "fifo": "a FIFO", "device": "a character device"}[kind]
    with pytest.raises(NotADirectoryError, match=f"^out_dir={out} is {words}, not a directory"):
        check_settings(reproduce_cfg("command=table2", f"out_dir={out}"))


@pytest.mark.parametrize("kind", SPECIAL)
def test_a_special_checkpoint_is_named_for_what_it_is(kind, tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    special(run / "checkpoint.pt", kind)
    with pytest.raises(CheckpointError, match=f"checkpoint.pt: {SPECIAL[kind]}, not a regular file"):
        load_checkpoint(run, "checkpoint")
    with pytest.raises(CheckpointError, match=f"^{SPECIAL[kind]}, not a regular file$"):
        read_torch(run / "checkpoint.pt")


def test_the_holder_of_a_run_is_read_from_a_regular_file_only(tmp_path):
    from uavrl.experiment.rundir import HOLDER, holder

    os.mkfifo(tmp_path / HOLDER)  # read, it would block: what it says is not known
    assert holder(tmp_path) == "pid unknown"
    assert special_kind(tmp_path / HOLDER) == "a FIFO" and special_kind(tmp_path / "missing") is None
    with pytest.raises(ValueError, match="is a FIFO, not a regular file"):
        read_regular_text(tmp_path / HOLDER)


@pytest.mark.parametrize("record", ['{"a": 1}', '["../victim"]', '["/etc/passwd"]', '["a", 3]'])
def test_a_damaged_record_of_written_files_is_refused(record, tmp_path, reproduce_cfg):
    """A record that is no list of names inside its folder is refused: nothing outside it is ever removed."""
    (tmp_path / Manifest.NAME).write_text(record)
    for overwrite in ("false", "true"):
        with pytest.raises(ValueError, match=r"is not a list of file names inside it: give another folder"):
            check_settings(reproduce_cfg("command=table2", f"out_dir={tmp_path}", f"overwrite={overwrite}"))


def test_overwrite_removes_nothing_through_a_link_out_of_the_folder(tmp_path, reproduce_cfg):
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    (elsewhere / "grid2x2").mkdir(parents=True)
    (elsewhere / "grid2x2" / "x").write_text("mine")
    out.mkdir()
    (out / "tensorboard").symlink_to(elsewhere)
    manifest = Manifest(out, "out_dir")
    manifest.record(out / "tensorboard" / "grid2x2" / "x")
    assert manifest.remove_all() == [] and (elsewhere / "grid2x2" / "x").read_text() == "mine"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    from uavrl.cli import compose_config
    from uavrl.train import train

    where = tmp_path_factory.mktemp("eval") / "run"
    overrides = ["agent=random", "env.grid=[3,3]", "eval.num_starts=2", "progress=false", f"run_dir={where}"]
    return train(compose_config("config", overrides))


def test_an_evaluation_with_other_settings_goes_beside_the_earlier_one(run_dir, compose_cfg, capsys):
    from uavrl.evaluate import print_evaluation

    def evaluated(*overrides) -> str:
        print_evaluation(compose_cfg(f"checkpoint={run_dir}", "eval.horizon=6", *overrides), [])
        return capsys.readouterr().out.splitlines()[-1]

    assert evaluated("eval.num_starts=2").startswith(f"metrics: {run_dir / 'eval.json'} ")
    first = (run_dir / "eval.json").read_text()
    assert evaluated("eval.num_starts=3").startswith(f"metrics: {run_dir / 'eval-2.json'} ")
    assert evaluated("eval.seed=5").startswith(f"metrics: {run_dir / 'eval-3.json'} ")
    assert (run_dir / "eval.json").read_text() == first  # the earlier evaluation stays
    assert evaluated("eval.num_starts=2").startswith(f"metrics: {run_dir / 'eval.json'} ")  # its own settings: again
    records = json.loads((run_dir / ".uavrl-evaluations.json").read_text())
    assert records["eval-3.json"]["seed"] == 5 and records["eval.json"]["num_starts"] == 2
    assert records["eval-2.json"]["num_starts"] == 3
    # an eval.json uavrl did not record (a user's, or an earlier version's) stays as it is
    (run_dir / ".uavrl-evaluations.json").unlink()
    assert evaluated("eval.num_starts=2").startswith(f"metrics: {run_dir / 'eval-4.json'} ")
    assert (run_dir / "eval.json").read_text() == first


def test_print_json_says_where_the_metrics_went(run_dir, compose_cfg, capsys):
    from uavrl.evaluate import print_evaluation

    print_evaluation(compose_cfg(f"checkpoint={run_dir}", "eval.horizon=7", "print_json=true"), [])
    out, err = capsys.readouterr()
    path = err.strip().removeprefix("metrics: ")
    assert json.loads(out) == json.loads(open(path).read())


@pytest.mark.parametrize("slot", [1e-300, 1e-100])
def test_a_slot_so_short_the_propulsion_power_overflows_names_slot_s(slot, tmp_path, command_exit):
    from uavrl.envs import InvalidOption, make_config

    with pytest.raises(InvalidOption) as err:
        make_config("paper", energy="rotary_wing", base=(-1, 0), slot_s=slot)
    assert err.value.option == "slot_s" and "propulsion power overflows" in str(err.value)
    line = f"train env.energy=rotary_wing env.base=[-1,0] env.slot_s={slot} agent=random"
    error = command_exit(line, tmp_path)
    assert error.startswith(f"error: env.slot_s={slot} is invalid: a move of one cell (env.cell_size=10.0 m)"), error


def test_a_manifest_writes_beside_a_users_file_and_over_its_own(tmp_path):
    manifest = Manifest(tmp_path, "checkpoint", ".uavrl-video-files.json")
    (tmp_path / "video.gif").write_text("mine")
    assert manifest.free(tmp_path / "video.gif") == tmp_path / "video-2.gif"
    (tmp_path / "video-2.gif").write_text("uavrl's")
    again = Manifest(tmp_path, "checkpoint", ".uavrl-video-files.json")  # read back from its record
    assert again.free(tmp_path / "video.gif") == tmp_path / "video-2.gif"  # its own: written over
    assert again.free(tmp_path / "battery.png") == tmp_path / "battery.png"  # free: taken
    assert not os.path.lexists(tmp_path / Manifest.NAME)  # reproduce's record is another file
    assert (tmp_path / "video.gif").read_text() == "mine"


def test_report_writes_over_no_report_of_a_users(run_dir, tmp_path):
    import shutil

    from uavrl.experiment.reporting import report

    study = tmp_path / "study"
    shutil.copytree(run_dir, study / "run")
    (study / "report.md").write_text("my own report\n")
    with pytest.raises(FileExistsError, match=r"^--out=.* holds report.md, which uavrl did not write there"):
        report([study], study, resamples=50)
    assert (study / "report.md").read_text() == "my own report\n"
    (study / "report.md").unlink()
    path = report([study], study, resamples=50)
    assert report([study], study, resamples=50) == path  # its own report: written again
    assert path.read_text().startswith("# Study report\n")
