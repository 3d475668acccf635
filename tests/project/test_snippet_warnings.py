"""The documentation's TorchRL Collector snippet runs without a warning of TorchRL's (a FutureWarning: a Collector of a
policy module over an env without ``is_init``, which torchrl 0.14 warns of and 0.15 fixes by adding InitTracker)."""

import re
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def collector_blocks() -> list[tuple[str, str]]:
    """``(file, code)`` of each Python block of README.md and docs/*.md that builds TorchRL's Collector, joined to the
    blocks of its file before it (a page's blocks share one namespace, as tests/project/test_doc_blocks.py runs
    them)."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    snippets = []
    for path in files:
        blocks = re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), flags=re.S)
        snippets += [
            (path.name, "\n".join(blocks[: i + 1]))
            for i, code in enumerate(blocks)
            if "from torchrl.collectors import Collector" in code
        ]
    return snippets


@pytest.mark.slow  # in CI's docs leg: the page's snippets in-process hold ~0.8 GB, over the fast suite's memory
def test_the_collector_snippet_runs_without_a_warning(tmp_path, monkeypatch, capsys):
    blocks = collector_blocks()
    assert blocks, "no Collector snippet found in README.md or docs/*.md"
    monkeypatch.chdir(tmp_path)
    for name, code in blocks:
        with warnings.catch_warnings():
            warnings.simplefilter("error", FutureWarning)
            exec(compile(code, name, "exec"), {"__name__": "snippet"})
    assert "tensor(" in capsys.readouterr().out
