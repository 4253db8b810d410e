"""The one-command study: stages (collect, train, evaluate, sweep, report) run in order, each from its own YAML.

`grits-lab pipeline experiments/quickstart.yaml` runs them; a finished stage is skipped and an
interrupted one resumes when the command runs again.
"""

from grits_lab.pipeline.pipeline_config import PipelineConfig, StageConfig, load_pipeline_config
from grits_lab.pipeline.pipeline_run import run_pipeline
from grits_lab.pipeline.stages import Layout

__all__ = ["Layout", "PipelineConfig", "StageConfig", "load_pipeline_config", "run_pipeline"]
