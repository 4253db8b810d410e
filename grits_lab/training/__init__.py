"""Generic training utilities shared by the policy and the predictor: device, EMA, LR schedule, checkpoints, logs."""

from grits_lab.training.checkpoints import load_checkpoint, save_checkpoint
from grits_lab.training.device import resolve_device, set_torch_threads
from grits_lab.training.ema import EMA
from grits_lab.training.metrics_log import MetricLogger, require_finite_loss
from grits_lab.training.schedule import warmup_cosine

__all__ = ["EMA", "MetricLogger", "load_checkpoint", "require_finite_loss", "resolve_device", "save_checkpoint", "set_torch_threads", "warmup_cosine"]
