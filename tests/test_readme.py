"""The README's Python examples run as written (each ```python block on its own)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from bwdesign.errors import MissingExtraError

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(), flags=re.S | re.M)


def test_the_readme_has_python_examples():
    assert len(BLOCKS) >= 2
    assert any("ClosedLoop(" in b and "simulate(" in b for b in BLOCKS)


@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i + 1}" for i in range(len(BLOCKS))])
def test_readme_python_block_runs(code, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # whatever an example writes lands here
    try:
        exec(compile(code, str(README), "exec"), {"__name__": "readme_example"})
    except MissingExtraError as err:  # an optional extra that is not installed
        pytest.skip(str(err))
    out = capsys.readouterr().out.splitlines()
    # "print(r.stable, r.metrics.maxe)  # True, 0.0127 um": the run prints what is stated
    for stable, value in re.findall(r"print\(r\.stable, r\.metrics\.maxe\)\s+# (\w+), (\S+)", code):
        first = out[0].split()
        assert first[0] == stable and f"{float(first[1]):.3g}" == value, out[0]
