"""The spillage predictor f_spillage(A_t, P_t) -> P(spill): encoders, model, training and the guidance objective."""

from grits_lab.spillage.guidance_objective import SpillageObjective, policy_to_predictor_affine, to_predictor_space
from grits_lab.spillage.model import CloudNormalizer, SpillagePredictor
from grits_lab.spillage.predictor_checkpoint import TrainedPredictor, load_predictor, save_predictor
from grits_lab.spillage.predictor_config import PredictorConfig, PredictorDataConfig, PredictorModelConfig, PredictorTrainConfig

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
    "save_predictor",
    "to_predictor_space",
]
