"""Commands the CLI prints for the user to run next are quoted for a POSIX shell: pasted, they name the same paths."""

from __future__ import annotations

import shlex

import pytest

from grits_lab.cli.evaluate_commands import report_hint
from grits_lab.tune.storage import dashboard_command


@pytest.mark.parametrize("path", ["results/evaluate", "results/my run", "results/$HOME's; rm -rf x", "résultats/ü"])
def test_the_printed_next_commands_split_back_into_the_same_paths(path):
    assert shlex.split(report_hint(path)) == ["grits-lab", "report", path]
    assert shlex.split(dashboard_command(f"{path}/journal.log")) == ["optuna-dashboard", f"{path}/journal.log"]
