"""Every study has its question, its committed commands and at most five findings (studies/commands.py)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from grits_lab.errors import InputError
from studies.commands import main, study_commands

ROOT = Path(__file__).resolve().parents[2]
STUDIES = sorted(p.parent for p in (ROOT / "studies").glob("*/README.md"))


def test_a_commands_block_joins_continued_lines_and_drops_comments(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("# S\n\n## Commands\n\n```bash\n# a comment\ngrits-lab evaluate a.yaml \\\n    --output-dir b   # why\n\n"
                      "grits-lab results render\n```\n")
    assert study_commands(readme) == ["grits-lab evaluate a.yaml --output-dir b", "grits-lab results render"]
    readme.write_text("# S\n\nNo commands.\n")
    with pytest.raises(InputError, match="no `## Commands` section"):
        study_commands(readme)


@pytest.mark.parametrize("study", STUDIES, ids=lambda p: p.name)
def test_each_study_states_its_question_commands_and_at_most_five_findings(study):
    text = (study / "README.md").read_text()
    assert "**Question.**" in text
    commands = study_commands(study / "README.md")
    assert commands and all(c.startswith(("grits-lab ", "python ")) for c in commands)
    findings = re.search(r"^## Findings\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert findings and 1 <= len(re.findall(r"^\d+\. ", findings.group(1), re.M)) <= 5
    assert (study / "__init__.py").is_file() and (study / "__main__.py").is_file()


def test_the_study_entry_prints_its_commands(capsys):
    assert main("protocol", []) == 0
    assert capsys.readouterr().out.splitlines() == study_commands(ROOT / "studies" / "protocol" / "README.md")
