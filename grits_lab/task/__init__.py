"""The task's stages after the scoop, as settings both the evaluation and the spillage trials' carry embed."""

from grits_lab.task.transfer_settings import TransferSettings

__all__ = ["TransferSettings"]
