"""The spillage predictor f_spillage(A_t, P_t) -> P(spill): encoders, model, training and the guidance objective."""

from grits_lab.spillage.checkpoint import TrainedPredictor, load_predictor, save_checkpoint
from grits_lab.spillage.config import PredictorConfig, PredictorDataConfig, PredictorModelConfig, PredictorTrainConfig
from grits_lab.spillage.guidance import SpillageObjective, policy_to_predictor_affine, to_predictor_space
from grits_lab.spillage.model import CloudNormalizer, SpillagePredictor

__all__ = [
    "CloudNormalizer",
    "PredictorConfig",
    "PredictorDataConfig",
    "PredictorModelConfig",
    "PredictorTrainConfig",
    "SpillageObjective",
    "SpillagePredictor",
    "TrainedPredictor",
    "load_predictor",
    "policy_to_predictor_affine",
    "save_checkpoint",
    "to_predictor_space",
]
