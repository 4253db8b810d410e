"""Dataset collection jobs: scripted demonstrations and perturbed spillage trials, run on the runners.

Each job plans picklable episode specs, hands the runner its work function (`demo_episode`,
`spillage_trial`) and writes the results through `grits_lab.data.format` (the storage layer).
"""

from grits_lab.collection.balance import BalancedAcceptor, Decision
from grits_lab.collection.demos import DemosConfig, demo_episode, plan_demos
from grits_lab.collection.driver import DatasetWriter, run_fixed_job
from grits_lab.collection.jobs import base_trajectory, load_collect_config, run_collection
from grits_lab.collection.spillage_trials import SpillageConfig, make_trial_spec, run_spillage_job, spillage_trial

__all__ = [
    "BalancedAcceptor",
    "DatasetWriter",
    "Decision",
    "DemosConfig",
    "SpillageConfig",
    "base_trajectory",
    "demo_episode",
    "load_collect_config",
    "make_trial_spec",
    "plan_demos",
    "run_collection",
    "run_fixed_job",
    "run_spillage_job",
    "spillage_trial",
]
