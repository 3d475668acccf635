"""The one logging path: TensorBoard event files in the run directory; and :func:`encode`, frames as GIF (or MP4)
bytes, which TensorBoard shows as an animated image and the video files hold (:mod:`uavrl.experiment.video`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tensorboard.compat.proto.summary_pb2 import Summary
from torch.utils.tensorboard import SummaryWriter
from torch.utils.tensorboard.summary import hparams as hparams_summaries

from uavrl.envs.rules import refuse, rule_of
from uavrl.experiment.io import EVENTS, save_bytes
from uavrl.schema import RunEvalSchema


class RunLogger:
    """Scalars against team steps.

    ``resume_step``: the points already in the directory up to this step stay,
    later ones are removed.  A resumed run passes its checkpoint's step, so the
    points a killed run logged after it give way to those logged again; a new
    run passes 0, so curves an earlier attempt left give way entirely.  Every
    curve has one point per logged step, for every reader: the files are
    merged into one without the later points (:func:`merge_events`), and the new
    file's ``purge_step`` says the same to TensorBoard.
    """

    def __init__(self, run_dir, resume_step: int | None = None):
        if resume_step:
            merge_events(Path(run_dir), resume_step)
        self.writer = SummaryWriter(log_dir=str(run_dir), purge_step=None if resume_step is None else resume_step + 1)

    def log(self, metrics: dict[str, float], step: int) -> None:
        for tag, value in metrics.items():
            self.writer.add_scalar(tag, value, step)

    def video(self, tag: str, frames, step: int, fps: int) -> None:
        """``[T, H, W, 3]`` uint8 frames as an animated GIF under ``tag`` (TensorBoard's Images tab plays it).

        The summary ``SummaryWriter.add_video`` writes, encoded by imageio: ``add_video`` needs moviepy (and
        ``moviepy.editor``, gone from moviepy 2), and without it logs nothing.
        """
        _, H, W, C = frames.shape
        image = Summary.Image(height=H, width=W, colorspace=C, encoded_image_string=encode(frames, fps))
        self.writer.file_writer.add_summary(Summary(value=[Summary.Value(tag=tag, image=image)]), step)

    def hparams(self, hparams: dict, metric_tags) -> None:
        """The run's settings for TensorBoard's HParams tab, beside the scalar tags ``metric_tags`` already logged.

        Unlike ``SummaryWriter.add_hparams``, this adds no point at step 0 to those tags.
        """
        for summary in hparams_summaries(hparams, {tag: None for tag in metric_tags}):
            self.writer.file_writer.add_summary(summary)

    def close(self) -> None:
        self.writer.close()


def merge_events(run_dir: Path, last_step: int) -> None:
    """Merge the event files of ``run_dir`` into one without the points after ``last_step``.

    Readers order a directory's event files by name, which holds the second it
    was made and the process id: two files of the same second can come in
    either order.  The merged file is named to come first (a second earlier
    than now at the latest), before the file the resumed run writes; a point
    logged twice (by a killed run and again after its resume) is kept once, the
    later one.  The HParams summary is dropped: the run writes it again when
    it ends.  A record a killed process left half written ends its file.
    """
    import io
    import time

    from tensorboard.backend.event_processing.event_file_loader import RawEventFileLoader
    from tensorboard.compat.proto import event_pb2
    from tensorboard.summary.writer.record_writer import RecordWriter

    files = sorted(run_dir.glob(EVENTS))
    if not files:
        return
    events = []
    for path in files:
        for record in RawEventFileLoader(str(path)).Load():
            event = event_pb2.Event.FromString(record)
            values = event.summary.value
            if (
                event.step > last_step
                or not values
                or any(v.metadata.plugin_data.plugin_name == "hparams" for v in values)
            ):
                continue  # file versions and session starts included: the merged file starts with its own
            events.append((tuple((v.tag, event.step) for v in values), record))
    last = {key: i for i, (keys, _) in enumerate(events) for key in keys}
    out = io.BytesIO()
    writer = RecordWriter(out)
    writer.write(event_pb2.Event(wall_time=time.time(), file_version="brain.Event:2").SerializeToString())
    for i, (keys, record) in enumerate(events):
        if all(last[key] == i for key in keys):
            writer.write(record)
    stamp = min(int(files[0].name.split(".")[3]), int(time.time()) - 1)
    merged = run_dir / f"events.out.tfevents.{stamp:010d}.merged"
    save_bytes(out.getvalue(), merged)
    for path in files:
        if path != merged:
            path.unlink()


def encode(frames: np.ndarray, fps: int, extension: str = ".gif") -> bytes:
    """``[T, H, W, 3]`` uint8 frames as an animated GIF (looping) or, with ``extension=".mp4"``, an H.264 MP4.

    Args:
        frames: ``[T, H, W, 3]`` uint8 frames.
        fps: frames per second.
        extension: ``".gif"`` or ``".mp4"`` (needs PyAV: ``pip install -e ".[video]"``).
    """
    import imageio.v3 as iio

    refuse("fps", fps, rule_of(RunEvalSchema, "video_fps"))
    if extension == ".gif":
        return iio.imwrite("<bytes>", frames, extension=".gif", duration=1000 / fps, loop=0)
    # H.264 in yuv420p needs even sides
    frames = np.pad(frames, ((0, 0), (0, frames.shape[1] % 2), (0, frames.shape[2] % 2), (0, 0)), constant_values=255)
    return iio.imwrite("<bytes>", frames, extension=".mp4", plugin="pyav", codec="libx264", fps=fps)
