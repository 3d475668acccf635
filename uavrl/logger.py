"""The one logging path: TensorBoard event files in the run directory."""
from __future__ import annotations

from torch.utils.tensorboard import SummaryWriter


class RunLogger:
    """Scalars against team steps; on resume, points past the checkpoint are purged first."""

    def __init__(self, run_dir, purge_step: int | None = None):
        self.writer = SummaryWriter(log_dir=str(run_dir), purge_step=purge_step)

    def log(self, metrics: dict[str, float], step: int) -> None:
        for tag, value in metrics.items():
            self.writer.add_scalar(tag, value, step)

    def hparams(self, hparams: dict, metrics: dict[str, float]) -> None:
        self.writer.add_hparams(hparams, metrics, run_name=".")

    def close(self) -> None:
        self.writer.close()
