"""Step a vector of the registered grits_lab/Scoop envs with random relative actions; nothing is trained.

    python examples/gym_vector_env.py --envs 2 --steps 20

Each env builds its own PyBullet world in this process (gymnasium.vector.SyncVectorEnv); an
AsyncVectorEnv runs one process per env the same way. Prints, per env, the spilled and scooped
particles and the IK failures after the last step.
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np

import grits_lab.sim  # noqa: F401  (registers the env under ENV_ID, grits_lab/Scoop-v<protocol version>)
from grits_lab.sim import ENV_ID


def run(n_envs: int = 2, steps: int = 20, food: str = "dried_jujube", level: str = "low", seed: int = 0) -> dict[str, np.ndarray]:
    """Step `n_envs` envs `steps` times; the last step's metrics per env as arrays (n_envs,)."""
    envs = gymnasium.vector.SyncVectorEnv([lambda: gymnasium.make(ENV_ID, food=food, level=level) for _ in range(n_envs)])
    try:
        envs.reset(seed=seed)  # env i gets seed + i
        envs.action_space.seed(seed)
        for _ in range(steps):
            _, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
        metrics = infos["metrics"]
        return {"spilled": metrics["spilled"], "scooped": metrics["scooped"], "ik_failures": infos["ik_failures"]}
    finally:
        envs.close()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--food", default="dried_jujube")
    parser.add_argument("--level", default="low")
    args = parser.parse_args()
    result = run(args.envs, args.steps, args.food, args.level)
    for i in range(args.envs):
        print(f"env {i}: spilled {result['spilled'][i]}, scooped {result['scooped'][i]}, IK failures {result['ik_failures'][i]}")
