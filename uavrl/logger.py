"""The one logging path: TensorBoard event files in the run directory."""

from __future__ import annotations

from pathlib import Path

from torch.utils.tensorboard import SummaryWriter
from torch.utils.tensorboard.summary import hparams as hparams_summaries

from uavrl.io import save_bytes
from uavrl.rundir import EVENTS


class RunLogger:
    """Scalars against team steps.

    ``resume_step``: the points already in the directory up to this step stay,
    later ones are removed.  A resumed run passes its checkpoint's step, so the
    points a killed run logged after it give way to those logged again; a new
    run passes 0, so curves an earlier attempt left give way entirely.  Every
    curve has one point per logged step, for every reader: the files are
    rewritten without the later points (:func:`truncate_events`), and the new
    file's ``purge_step`` says the same to TensorBoard.
    """

    def __init__(self, run_dir, resume_step: int | None = None):
        if resume_step:
            for events in sorted(Path(run_dir).glob(EVENTS)):
                truncate_events(events, resume_step)
        self.writer = SummaryWriter(log_dir=str(run_dir), purge_step=None if resume_step is None else resume_step + 1)

    def log(self, metrics: dict[str, float], step: int) -> None:
        for tag, value in metrics.items():
            self.writer.add_scalar(tag, value, step)

    def hparams(self, hparams: dict, metric_tags) -> None:
        """The run's settings for TensorBoard's HParams tab, beside the scalar tags ``metric_tags`` already logged.

        Unlike ``SummaryWriter.add_hparams``, this adds no point at step 0 to those tags.
        """
        for summary in hparams_summaries(hparams, {tag: None for tag in metric_tags}):
            self.writer.file_writer.add_summary(summary)

    def close(self) -> None:
        self.writer.close()


def truncate_events(path: Path, last_step: int) -> None:
    """Rewrite the event file ``path`` (atomically) without its points after ``last_step`` and its HParams summary,
    which the run writes again when it ends.  A record a killed process left half written ends the file."""
    import io

    from tensorboard.backend.event_processing.event_file_loader import RawEventFileLoader
    from tensorboard.compat.proto import event_pb2
    from tensorboard.summary.writer.record_writer import RecordWriter

    dropped, out = 0, io.BytesIO()
    writer = RecordWriter(out)
    for record in RawEventFileLoader(str(path)).Load():
        event = event_pb2.Event.FromString(record)
        hparams = any(value.metadata.plugin_data.plugin_name == "hparams" for value in event.summary.value)
        if event.step > last_step or hparams:
            dropped += 1
            continue
        writer.write(record)
    if dropped:
        save_bytes(out.getvalue(), path)
