"""The studies' tests use the evaluation tests' tiny checkpoints."""

from tests.evaluation.conftest import models, recorded_run  # noqa: F401
