"""Behaviour kept bit for bit: ``benchmarks/fingerprint.py`` against the digests recorded in
``benchmarks/results/fingerprint.txt`` (on the torch, processor and vector instructions they were recorded with:
elsewhere floating-point kernels may round differently, and the test skips)."""

import platform
import subprocess
import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[2]
RECORDED = ROOT / "benchmarks" / "results" / "fingerprint.txt"


@pytest.mark.slow
def test_every_setting_gives_the_recorded_digests():
    recorded = RECORDED.read_text().splitlines()
    here = f"torch {torch.__version__} on {platform.machine()} {torch.backends.cpu.get_cpu_capability()}"
    if recorded[0] != f"# {here}":
        pytest.skip(f"digests recorded with {recorded[0][2:]}, not {here}")
    run = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "fingerprint.py")], capture_output=True, text=True, check=True
    )
    changed = [
        f"{old} -> {new.split()[-1]}" for old, new in zip(recorded, run.stdout.splitlines(), strict=True) if old != new
    ]
    assert not changed, "behaviour changed: " + "; ".join(changed)
