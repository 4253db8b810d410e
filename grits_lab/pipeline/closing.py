"""The lines a pipeline run ends with: what the predictor learned, what the sweep chose, what guidance did, what the episodes decide.

Read from the stages' own outputs under the pipeline's output folder (the predictor run's
history.json and heldout.json, the sweep's summary.json, the evaluation's records), so a run that
skipped every stage prints the same lines as the run that made them.
"""

from __future__ import annotations

import json
from pathlib import Path

from grits_lab.pipeline.stages import Layout


def closing_lines(layout: Layout, stages: list[str]) -> list[str]:
    """One line per finding of the configured `stages` whose outputs exist; none for the others."""
    lines: list[str] = []
    if "predictor" in stages:
        from grits_lab.report.predictor_quality import read_predictor

        if (quality := read_predictor(layout.predictor_dir("predictor"))) is not None:
            lines.append(quality.line())
    summary_path = layout.sweep_dir / "summary.json"
    if "sweep" in stages and summary_path.is_file():
        lines.append(sweep_line(json.loads(summary_path.read_text()), layout.sweep_dir))
    if "evaluate" in stages and (layout.evaluate_dir / "episodes.parquet").is_file():
        from grits_lab.report.guidance_effect import guided_episodes, plan_effect, plan_effect_line
        from grits_lab.report.headline import decision_sentence, headline_table
        from grits_lab.report.run_records import load_run

        run = load_run(layout.evaluate_dir, exclude=layout.report_dir)
        lines += [f"guidance, {plan_effect_line(e)}" for e in plan_effect(guided_episodes(run.episodes)).values()]
        if run.episodes is not None:
            lines.append(decision_sentence(headline_table(run.episodes)))
    return lines


def sweep_line(summary: dict, folder: Path) -> str:
    """"sweep: best rho 0.8, s 24 (trial 2: success 0.75, spillage 0.00 over 4 episodes; DP ...); front ...; optuna-dashboard ..."."""
    best = summary.get("best")
    if not best:
        return f"sweep: no completed trial yet ({folder})"
    def rates(a: dict) -> str:
        return f"success {a['success_rate']:.2f}, spillage {a['spillage_rate']:.2f}"
    text = (f"sweep: best rho {best['rho']:.3g}, s {best['s']} (trial {best['trial']}: {rates(best)} over "
            f"{summary.get('episodes_per_trial')} validation episodes")
    for method, reference in (summary.get("reference") or {}).items():
        text += f"; {method} on the same episodes: {rates(reference)}"
    front = ", ".join(f"rho {t['rho']:.3g} s {t['s']} ({rates(t)})" for t in summary.get("pareto_front", []))
    return text + f"); Pareto front: {front}; {summary.get('dashboard', '')}"
