"""The spillage predictor f_spillage(A_t, P_t) -> P(spill): encoders, model, training and the guidance objective."""

from grits_lab.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "checkpoint": ["TrainedPredictor", "load_predictor", "save_predictor"],
    "config": ["PredictorConfig", "PredictorDataConfig", "PredictorModelConfig", "PredictorTrainConfig"],
    "guidance_objective": ["SpillageObjective", "policy_to_predictor_affine", "to_predictor_space"],
    "model": ["CloudNormalizer", "SpillagePredictor"],
})
