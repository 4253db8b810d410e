"""Benchmark of the IK solves the stages after the scoop make, per call on the Panda's kinematic copy.

Prints one JSON object. Poses are a lift's: the spoon rising 10 cm and levelling from a tipped
pose, from the wound wrist a scoop can leave (joints 6 and 7 near their upper limits) and from the
rest posture. Three solvers on the same poses, each seeded at the last answer as the transfer
seeds them: PyBullet's solver to the fine residual (`PandaKinematics.solve`, FINE_IK, as every
physics step of the lift runs it), its damped least-squares refinement (`refine`, run only where
PyBullet's answer misses), and the heading-free five-dimensional solve of the lift scoop-v11 tries
when no option passes (`solve_heading_free`). Ratios are taken against `solve` in the same run.

    python benchmarks/bench_transfer_ik.py
    python benchmarks/bench_transfer_ik.py --repeats 5 --poses 40
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time

import numpy as np

from grits_lab.geometry import axis_angle_matrix
from grits_lab.sim.robot import FINE_IK, REST_POSE, PandaKinematics

WOUND = (-0.2, 0.18, -0.325, -2.363, -1.683, 3.582, 1.951)  # the oracle's fudge, low, trial 3 after its scoop (scoop-v10)
PIVOT = np.array([0.0, 0.05, 0.1])  # a point of the grasp frame held by the heading-free solve


def lift_targets(kin: PandaKinematics, start: np.ndarray, n: int) -> list[np.ndarray]:
    """(4, 4) grasp targets: from the pose at joints `start`, 10 cm up while turning 30 degrees level."""
    first = kin.forward(start)
    out = []
    for f in np.linspace(0.0, 1.0, n + 1)[1:]:
        m = first.copy()
        m[:3, :3] = axis_angle_matrix([0.0, 1.0, 0.0], np.radians(30.0) * f) @ first[:3, :3]
        m[2, 3] += 0.10 * f
        out.append(m)
    return out


def time_calls(solve, targets: list[np.ndarray], seed: np.ndarray, repeats: int) -> float:
    """Median over `repeats` of the mean ms per call along `targets`, each seeded at the last answer."""
    runs = []
    for _ in range(repeats):
        q = seed.copy()
        start = time.perf_counter()
        for target in targets:
            q = solve(target, q)
        runs.append((time.perf_counter() - start) * 1000 / len(targets))
    return statistics.median(runs)


def converged_share(kin: PandaKinematics, key: str, solve, targets: list[np.ndarray], seed: np.ndarray) -> float:
    """Share of the poses along the lift whose answer is within FINE_IK (for the heading-free solve, of its five task residuals)."""
    q, hits = seed.copy(), 0
    for target in targets:
        q = solve(target, q)
        e = kin.solve_heading_free(target, q, PIVOT, FINE_IK, limit_step=0.0, iterations=0)[1] if key == "heading_free" \
            else kin.residual(target, q)
        hits += FINE_IK.reached(float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])))
    return round(hits / len(targets), 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs along the lift; the median is reported")
    parser.add_argument("--poses", type=int, default=20, help="poses along the lift")
    args = parser.parse_args()
    if args.repeats < 1 or args.poses < 1:
        parser.error("--repeats and --poses must be at least 1")
    kin = PandaKinematics()
    result = {"machine": platform.processor() or platform.machine(), "python": platform.python_version(),
              "poses": args.poses, "repeats": args.repeats}
    solvers = {
        "solve_fine": lambda t, q: kin.solve(t, q, 0.01, 0.15, rest_pull=False, converged=FINE_IK).joints,
        "refine_fine": lambda t, q: kin.refine(t, q, FINE_IK),
        "heading_free": lambda t, q: kin.solve_heading_free(t, q, PIVOT, FINE_IK)[0],
    }
    for name, start in (("wound_wrist", np.array(WOUND)), ("rest_posture", np.array(REST_POSE))):
        targets = lift_targets(kin, start, args.poses)
        ms = {key: round(time_calls(fn, targets, start, args.repeats), 3) for key, fn in solvers.items()}
        result[name] = {f"{key}_ms_per_call": value for key, value in ms.items()}
        result[name].update({f"{key}_over_solve": round(ms[key] / ms["solve_fine"], 2) for key in ("refine_fine", "heading_free")})
        result[name].update({f"{key}_converged": converged_share(kin, key, fn, targets, start) for key, fn in solvers.items()})
    kin.close()
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
