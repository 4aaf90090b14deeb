"""The README's figures are generated: each marked block is its script's rendering of the stored
payload (``benchmarks/readme_figures/*.json``, or the accuracy gate's baseline, which
``tests/test_accuracy_gate.py`` recomputes from the code).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import readme  # noqa: E402


def test_every_block_of_the_readme_is_its_rendered_payload():
    problems = readme.check()
    assert not problems, "\n".join(problems) + (
        "\nre-render with 'python benchmarks/readme.py --render' (or measure afresh)")


@pytest.mark.parametrize("name", list(readme.BLOCKS))
def test_each_stored_payload_names_its_command_and_commit(name):
    block = readme.BLOCKS[name]
    entry = readme.stored(block)
    assert entry["command"] == block.command
    if hasattr(block.module(), "measure"):
        assert entry["commit"] and entry["date"] and entry["payload"]
        assert entry["command"].split("python ")[-1].split()[0] == f"benchmarks/{block.script}.py"


def test_the_accuracy_block_is_the_gate_baseline():
    baseline = json.loads((ROOT / "benchmarks" / "accuracy_baseline.json").read_text())
    block = readme.render(readme.BLOCKS["accuracy"])
    for name, entry in baseline["figures"].items():
        assert f"`{name}`" in block and f"{entry['value']:.4g}" in block


def test_a_hand_edit_is_caught(tmp_path):
    text = (ROOT / "README.md").read_text()
    name = next(iter(readme.BLOCKS))
    start, end = readme.blocks_in(text)[name]
    edited = text[:end] + "| an edited row |\n" + text[end:]
    path = tmp_path / "README.md"
    path.write_text(edited)
    problems = [p for p in readme.check(path) if f"block {name!r}" in p]
    assert len(problems) == 1 and "an edited row" in problems[0]
    path.write_text(readme.rewrite(edited, [name], path))
    assert not [p for p in readme.check(path) if f"block {name!r}" in p]


def test_broken_markers_are_located(tmp_path):
    path = tmp_path / "README.md"
    text = "a\n<!-- figures:x:begin -->\nb\n<!-- figures:y:end -->\n"
    with pytest.raises(ValueError, match=r"README.md:4: end of 'y' without its begin"):
        readme.blocks_in(text, path)
    with pytest.raises(ValueError, match="'x' has no end marker"):
        readme.blocks_in("<!-- figures:x:begin -->\n", path)
    with pytest.raises(ValueError, match="no block"):
        readme.rewrite("text\n", ["simulate"], path)
