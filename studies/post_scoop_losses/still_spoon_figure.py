"""Does a heaped spoon held still keep its heap? The arm at the scoop's 30 solver iterations, the
spoon made static, and the arm at the transfer's 100 (studies/post_scoop_losses/still_spoon.py).

    python studies/post_scoop_losses/still_spoon_figure.py                     # 6 foods x 2 seeds x 3 settings, ~6 min on 2 cores
    python studies/post_scoop_losses/still_spoon_figure.py --foods red_bean:high --seeds 1

Writes still_spoon.csv (one row per food, level, seed and setting) and still_spoon.png (grains
that moved more than 1 mm and more than 1 cm in 4 s, per setting) to --output-dir.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from tqdm import tqdm  # noqa: E402

from studies.post_scoop_losses.still_spoon import hold_heaped_spoon  # noqa: E402
from grits_lab.task.transfer_settings import TransferSettings  # noqa: E402

SETTINGS = {  # label: (holder, solver iterations; None = the scoop's)
    "arm, 30 iterations (the scoop's)": ("arm", None),
    "static spoon, 30 iterations": ("static", None),
    f"arm, {TransferSettings().solver_iterations} iterations (the transfer's)": ("arm", TransferSettings().solver_iterations),
}
DEFAULT_FOODS = ["red_bean:high", "soybeans:high", "nuts:high", "ramen_snack:high", "mung_beans:medium", "chocolate_balls:high"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--foods", nargs="+", default=DEFAULT_FOODS, metavar="FOOD:LEVEL")
    parser.add_argument("--seeds", type=int, default=2, help="seeds 0..N-1 per food (default 2)")
    parser.add_argument("--output-dir", type=Path, default=Path("results/still_spoon"))
    args = parser.parse_args()
    pairs = []
    for item in args.foods:
        if item.count(":") != 1:
            parser.error(f"--foods takes FOOD:LEVEL, got {item!r}")
        pairs.append(tuple(item.split(":")))
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, got {args.seeds}")
    rows = []
    jobs = [(food, level, seed, label) for food, level in pairs for seed in range(args.seeds) for label in SETTINGS]
    for food, level, seed, label in tqdm(jobs, unit="hold"):
        holder, iterations = SETTINGS[label]
        out = hold_heaped_spoon(food, level, seed, iterations=iterations, holder=holder)
        moved = out["moved"]
        rows.append({"food": food, "level": level, "seed": seed, "setting": label, "grains": len(moved),
                     "above_spoon_rim": out["above_spoon_rim"], "moved_over_1mm": int((moved > 0.001).sum()),
                     "moved_over_1cm": int((moved > 0.01).sum()), "median_moved_mm": float(np.median(moved) * 1000)})
    table = pd.DataFrame(rows)
    args.output_dir.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.output_dir / "still_spoon.csv", index=False)
    totals = table.groupby("setting", sort=False)[["grains", "moved_over_1mm", "moved_over_1cm"]].sum()
    print(totals.to_string())
    fig, ax = plt.subplots(figsize=(8, 3.6))
    x = np.arange(len(totals))
    ax.bar(x - 0.2, totals.moved_over_1mm / totals.grains * 100, 0.4, label="moved > 1 mm")
    ax.bar(x + 0.2, totals.moved_over_1cm / totals.grains * 100, 0.4, label="moved > 1 cm (left the heap)")
    ax.set_xticks(x, [s.replace(" (", "\n(") for s in totals.index], fontsize=8)
    ax.set_ylabel("% of grains on the spoon")
    ax.set_title(f"A heaped spoon held still for 4 s ({len(table) // len(SETTINGS)} heaps, {int(totals.grains.iloc[0])} grains)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.output_dir / "still_spoon.png", dpi=120)
    print(f"written: {args.output_dir / 'still_spoon.csv'}, {args.output_dir / 'still_spoon.png'}")


if __name__ == "__main__":
    main()
