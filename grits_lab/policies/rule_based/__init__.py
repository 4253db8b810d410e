"""Rule-based baseline (paper Sec. V-B): centre, measure the food height, rotate, dig 5 cm, fixed scooping motion."""

from grits_lab.policies.rule_based.controller_rule_based import RuleBasedController, pitch_pose, food_surface_height

__all__ = ["RuleBasedController", "food_surface_height", "pitch_pose"]
