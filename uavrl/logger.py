"""The one logging path: TensorBoard event files in the run directory."""

from __future__ import annotations

from tensorboard.compat.proto.summary_pb2 import Summary
from torch.utils.tensorboard import SummaryWriter
from torch.utils.tensorboard.summary import hparams as hparams_summaries


class RunLogger:
    """Scalars against team steps.

    ``resume_step``: the points already in the directory up to this step stay,
    later ones are purged (TensorBoard drops them on reading).  A resumed run
    passes its checkpoint's step, so the points a killed run logged after it
    give way to those logged again; a new run passes 0, so curves an earlier
    attempt left give way entirely.  Every curve has one point per logged step.
    """

    def __init__(self, run_dir, resume_step: int | None = None):
        self.writer = SummaryWriter(log_dir=str(run_dir), purge_step=None if resume_step is None else resume_step + 1)

    def log(self, metrics: dict[str, float], step: int) -> None:
        for tag, value in metrics.items():
            self.writer.add_scalar(tag, value, step)

    def video(self, tag: str, frames, step: int, fps: int) -> None:
        """``[T, H, W, 3]`` uint8 frames as an animated GIF under ``tag`` (TensorBoard's Images tab plays it).

        The summary ``SummaryWriter.add_video`` writes, encoded by imageio: ``add_video`` needs moviepy (and
        ``moviepy.editor``, gone from moviepy 2), and without it logs nothing.
        """
        from uavrl.video import encode

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
