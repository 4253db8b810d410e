"""Assemble a report from a run directory: read records, build tables and figures, write every format.

Output layout (OUT defaults to RUN_DIR/report):

    report.md         all tables (Markdown) with the figures linked
    report.html       one self-contained page: all tables, figures embedded, provenance
    report.tex        all tables as booktabs LaTeX (latex/<table>.tex holds each alone)
    csv/<table>.csv   the numbers behind every table (rates, Wilson bounds, counts)
    figures/*.png     bar charts with Wilson 95% error bars, per-food stacks, heatmaps, sweep front
    provenance.json   what produced the records and the report
    videos/*.mp4      with `videos=N`: replayed episodes, shown side by side in report.html

The page opens with the headline comparison (Diffusion Policy vs GRITS, with counts); lists of
missing cells are collapsed under it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from grits_lab.io import ensure_writable_dir, write_json_atomic, write_text_atomic
from grits_lab.report import figures
from grits_lab.report.run_records import RunData, load_run
from grits_lab.report.provenance import episode_counts, error_messages, protocol_summary, report_provenance
from grits_lab.report.real_robot import real_robot_table
from grits_lab.report.run_compare import paired_methods_table, paired_section_title
from grits_lab.report.guidance_effect import (
    guidance_by_plan_table,
    guidance_figure,
    guidance_table,
    guided_episodes,
    plan_effect,
    plan_effect_line,
)
from grits_lab.report.headline import NOTHING_TO_ACT_ON, decision_sentence, episodes_sentence, headline_sentence, headline_table
from grits_lab.report.predictor_quality import PredictorQuality, find_predictors
from grits_lab.spillage.classifier_metrics import DEGENERATE_SPREAD
from grits_lab.report.render import (
    Collapsed,
    Preformatted,
    ReportFigure,
    Section,
    render_html,
    render_markdown,
    table_latex,
    to_json_text,
    write_csv,
)
from grits_lab.report.spill_tables import delivery_table, load_loss_figure, spill_attribution_table
from grits_lab.report.sweep import summarize_sweep, sweep_reference_table, sweep_tables
from grits_lab.report.tables import (
    ReportTable,
    all_variants,
    breakdown_long,
    breakdown_tables,
    claims_table,
    failure_table,
    method_table,
    per_food_table,
    setting_table,
)
from grits_lab.report.vocabulary import ABLATION_METHODS, MAIN_METHODS, PAPER_LABEL, SIM_LABEL, method_display


@dataclass
class ReportResult:
    out_dir: Path
    files: list[Path] = field(default_factory=list)
    tables: list[ReportTable] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)


def default_out_dir(run_dir: str | Path) -> Path:
    run_dir = Path(run_dir)
    return (run_dir if run_dir.is_dir() else run_dir.parent) / "report"


def build_report(run_dir: str | Path, out_dir: str | Path | None = None, *, also: Sequence[str | Path] = (),
                 videos: int = 0, replay: Callable[..., Any] | None = None, progress: bool = False,
                 training: Sequence[str | Path] = (), real: Sequence[str | Path] = (), methods: Sequence[str] = ()) -> ReportResult:
    """Write the report of RUN_DIR into `out_dir` (default RUN_DIR/report).

    also: further run directories whose episode records are reported beside RUN_DIR's (a method
    evaluated at several (rho, s) gets one row per setting; grits_lab/report/run_records.py).

    videos: replay up to this many episodes per food (grits_lab/report/videos.py has the rule)
    under Diffusion Policy and GRITS and show them side by side; `replay` is the function that
    replays one recorded episode into a video (`grits_lab.report.replay.replay_episode`).
    With videos = 0 (the default) nothing is replayed and no simulator is needed. progress: a
    bar on stderr while the videos are replayed.

    training: training run directories (policy, BC, predictor) whose `curves.png` files, found up
    to two folders deep, are shown in a "Training" section with each run's last logged values.

    real: CSV files of real-robot trials (grits_lab/report/real_trials.py), shown with the
    simulation and the paper's numbers in one table, "Real robot beside the simulation".

    methods: report only these methods' episodes (load_run).
    """
    out = Path(out_dir) if out_dir is not None else default_out_dir(run_dir)
    run = load_run(run_dir, exclude=out, also=also, methods=methods)
    real_table = real_robot_table(run.episodes, real) if real else None  # a bad file fails before anything is written
    ensure_writable_dir(out)
    result = ReportResult(out)
    predictors = find_predictors([d for d in training if Path(d).name == "predictor" or (Path(d) / "history.json").is_file()])
    steering = next((p for p in predictors if p.name == "predictor"), predictors[0] if predictors else None)
    degenerate = degenerate_guidance(steering, run.episodes)
    sections = (_results_sections(run, out, result, degenerate) + _training_sections(training, out, result)
                + [_provenance_section(run, out, result)])
    if videos > 0 and run.episodes is not None:
        if replay is None:
            raise ValueError("videos > 0 needs a replay function")
        sections.insert(0, _videos_section(run, out, videos, replay, result, progress))
    missing = list(dict.fromkeys(note for table in result.tables for note in table.notes if note.startswith("Missing")))
    result.missing = missing
    overview = Section("Overview", [
        f"Simulated results of run {run.run_dir}, beside the paper's real-robot numbers where the paper states "
        f"them. Labels: '{SIM_LABEL}' for this run, '{PAPER_LABEL}' for the paper. Rates carry Wilson 95% "
        "intervals and episode counts; a method or food without records is shown as — and listed below, never as zero."
        + (f" Records of {', '.join(str(p) for p in run.also_runs)} are reported beside this run's." if run.also_runs else ""),
        f"Task protocol: {protocol_summary(run.episodes)} (docs/protocol.md).",
        Collapsed(f"Missing data: {len(missing)} notes (click to list)", missing) if missing else "Missing data: none.",
    ])
    if real_table is not None:
        sections.insert(0, Section("Real robot beside the simulation", [_table(real_table, out, result)]))
    sections.insert(0, overview)
    if run.episodes is not None and not is_sweep_records(run):
        headline = headline_table(run.episodes, degenerate=degenerate)
        sections.insert(0, Section("Headline: Diffusion Policy vs GRITS", [
            episodes_sentence(run.episodes), headline_sentence(headline), decision_sentence(headline),
            _table(headline, out, result), *([steering.line()] if steering else [])]))
    title = f"GRITS reproduction report: {report_title(run)}"
    result.files.append(_write(out / "report.md", render_markdown(title, sections, out)))
    result.files.append(_write(out / "report.html", render_html(title, sections)))
    result.files.append(_write(out / "report.tex", "\n".join(table_latex(t) for t in result.tables)))
    result.files = list(dict.fromkeys(result.files))
    return result


def degenerate_guidance(steering: PredictorQuality | None, episodes: Any) -> str | None:
    """Why GRITS's guidance had nothing to act on, or None: the predictor run's own verdict
    (`degenerate_reason` on its validation chunks), else a P(spill) that barely varied across the
    guided plans of the records (standard deviation below DEGENERATE_SPREAD)."""
    if steering is not None and steering.degenerate:
        return steering.degenerate
    for effect in plan_effect(guided_episodes(episodes)).values():
        if effect["p_spill_spread"] < DEGENERATE_SPREAD:
            return (f"its P(spill) barely varies across {effect['method_name']}'s {effect['plans']} plans "
                    f"(standard deviation {effect['p_spill_spread']:.4f})")
    return None


def report_title(run: RunData) -> str:
    """The experiment the records name (their `run_id`) and the protocol they ran under; the run's
    folder only where the records name no experiment."""
    episodes = run.episodes
    names = list(dict.fromkeys(episodes["run_id"].dropna().astype(str))) if episodes is not None and "run_id" in episodes.columns else []
    experiment = ", ".join(names) if names else run.run_dir.resolve().name
    return f"{experiment}, protocol {protocol_summary(episodes)}" if episodes is not None and len(episodes) else experiment


def _results_sections(run: RunData, out: Path, result: ReportResult, degenerate: str | None = None) -> list[Section]:
    episodes = run.episodes
    sections = []
    if episodes is not None and is_sweep_records(run):
        # Records of sweep trials evaluate one method at many (rho, s): the paper's figures would
        # pool or multiply them, so they are summarized per setting instead.
        sections.append(Section("Sweep: per guidance setting", [
            "These records are the sweep's per-trial evaluation records; the paper's figures (Fig. 5, 6, 8) "
            "are drawn from `grits-lab evaluate` runs.",
            _table(setting_table(episodes), out, result),
        ]))
    elif episodes is not None:
        claims = claims_table(episodes)
        fig5 = method_table(episodes, MAIN_METHODS, "fig5_overall", "Fig. 5: task success, spillage and scoop failure",
                            "Every method over all evaluated foods and quantity levels.", extra=True)
        fig8 = method_table(episodes, ABLATION_METHODS, "fig8_ablation", "Fig. 8: spillage predictor ablation",
                            "GRITS with a raw camera cloud, with a PointNet++ encoder, and with the composite cloud + DP3 encoder.")
        fig6 = per_food_table(episodes)
        breakdown = breakdown_tables(episodes)
        sections.append(Section("The paper beside the simulation", [_table(claims, out, result)]))
        sections.append(Section("Fig. 5: overall results", [
            _table(fig5, out, result),
            _figure("fig5_overall", fig5.title, "Bars: simulation; white diamonds: real robot (paper); error bars: Wilson 95%.",
                    figures.method_bars(fig5.data, out / "figures" / "fig5_overall.png", fig5.title), result),
        ]))
        items = [_table(fig6, out, result)]
        if not fig6.data.empty:
            items.append(_figure("fig6_per_food", fig6.title, fig6.caption,
                                 figures.per_food_stacks(fig6.data, out / "figures" / "fig6_per_food.png", fig6.title), result))
        sections.append(Section("Fig. 6: per food", items))
        if (paired := paired_methods_table(episodes)) is not None:
            sections.append(Section(paired_section_title(paired.data), [_table(paired, out, result)]))
        lost = [_table(failure_table(episodes), out, result), _table(spill_attribution_table(episodes), out, result),
                _table(delivery_table(episodes), out, result)]
        if (loss_png := load_loss_figure(episodes, out / "figures" / "load_loss.png")) is not None:
            lost.append(_figure("load_loss", "Food lost after the scoop against the heap above the spoon's rim",
                                "One point per episode that lifted food, coloured by the stage that lost it.", loss_png, result))
        sections.append(Section("Why tasks failed", lost))
        sections.append(Section("Fig. 8: predictor ablation", [
            _table(fig8, out, result),
            _figure("fig8_ablation", fig8.title, "Bars: simulation; error bars: Wilson 95%.",
                    figures.method_bars(fig8.data, out / "figures" / "fig8_ablation.png", fig8.title), result),
        ]))
        guided = guided_episodes(episodes)
        if not guided.empty:
            table = guidance_table(guided)
            effects = [plan_effect_line(e) + "." for e in plan_effect(guided).values()]
            if degenerate:
                effects.insert(0, f"The predictor is degenerate ({degenerate}): {NOTHING_TO_ACT_ON}.")
            sections.append(Section("Guidance: what it changed", [
                *effects,
                _table(table, out, result),
                _figure("guidance", table.title, "Left: the predictor's P(spill) of each guided episode's plans before the first and "
                        "after the last guidance step (lines pair one episode). Right: the guidance displacement per plan.",
                        guidance_figure(guided, out / "figures" / "guidance.png"), result),
                *([_table(by_plan, out, result)] if not (by_plan := guidance_by_plan_table(guided)).data.empty else []),
            ]))
        long = ReportTable("breakdown_long", "Per method x food x level (long form)", "", episodes.head(0), breakdown_long(episodes))
        result.files.append(write_csv(long, out / "csv" / "breakdown_long.csv"))
        heatmap = figures.breakdown_heatmap({t.key.removeprefix("breakdown_"): t.data for t in breakdown},
                                            all_variants(episodes), out / "figures" / "breakdown_heatmap.png")
        sections.append(Section("Per food x quantity level", [
            *(_table(t, out, result) for t in breakdown),
            _figure("breakdown_heatmap", "Per food x quantity level", "Rates per cell with k/n; hatched: no episodes.", heatmap, result),
            "csv/breakdown_long.csv holds every (method, food, level) cell with Wilson 95% intervals.",
        ]))
    if run.trials is not None:
        summary = summarize_sweep(run.trials, run.best_params)
        best_file = str(run.best_params_file) if run.best_params_file else None
        items = [_table(t, out, result) for t in sweep_tables(summary, run.best_params, best_file)]
        for every_trial in (False, True):
            against = sweep_reference_table(run.sweep_reference, every_trial=every_trial)
            if against is not None:
                items.append(_table(against, out, result))
        if run.best_params_text:
            # The file as written: its comments say how the best trial was chosen and how it compares.
            items.append(Preformatted(f"Best parameters file: {best_file}", run.best_params_text, "yaml"))
        front = figures.sweep_front(summary, out / "figures" / "sweep_front.png")
        if front is not None:
            items.append(_figure("sweep_front", "Sweep: objectives of completed trials", "Red: Pareto front; star: the paper's defaults.", front, result))
        sections.append(Section(f"Sweep summary ({run.trials_file})", items))
    return sections


def _training_sections(dirs: Sequence[str | Path], out: Path, result: ReportResult) -> list[Section]:
    """One figure per training run: its curves (drawn by the run's MetricLogger), copied into figures/."""
    import pandas as pd

    items: list[Any] = []
    for root in map(Path, dirs):
        for curves in sorted(p for pattern in ("curves.png", "*/curves.png", "*/*/curves.png") for p in root.glob(pattern)):
            run = curves.parent
            name = "_".join(run.relative_to(root.parent).parts)
            copy = out / "figures" / f"training_{name}.png"
            copy.parent.mkdir(parents=True, exist_ok=True)
            copy.write_bytes(curves.read_bytes())
            last = pd.read_csv(run / "metrics.csv").ffill().iloc[-1] if (run / "metrics.csv").is_file() else None
            shown = "" if last is None else "Last logged step {}: {}.".format(
                int(last["step"]), ", ".join(f"{k} {last[k]:.4g}" for k in last.index if k != "step" and pd.notna(last[k])
                                             and (k.endswith("loss") or k.startswith("val_") or k.startswith("rollout_"))))
            items.append(_figure(f"training_{name}", f"Training: {run}", f"Loss, learning rate and validation metrics "
                                 f"per step (an epoch for the predictor), from {run / 'metrics.csv'}. {shown}", copy, result))
    return [Section("Training", items)] if items else []


def _videos_section(run: RunData, out: Path, per_food: int, replay: Callable[..., Any], result: ReportResult,
                    progress: bool) -> Section:
    from grits_lab.report.videos import choose_episodes, film_picks

    picks = choose_episodes(run.episodes, per_food)
    rows = film_picks(run.run_dir, picks, replay, out, progress=progress)
    result.files += [out / v.path for row in rows for v in row.videos if v.path]
    intro = (f"Replayed from their records (same seed, checkpoints and guidance), up to {per_food} per food, chosen in this "
             "order: Diffusion Policy spilled and GRITS did not; both spilled; GRITS spilled and DP did not; neither "
             "spilled (ties: lowest level, then trial). Each caption says whether the replay reproduced the record. "
             "The videos are files in videos/ beside this page.")
    return Section("Episodes to watch", [intro, *rows] if rows else [intro, "No episode of Diffusion Policy or GRITS to replay."])


def is_sweep_records(run: RunData) -> bool:
    """True when every record file lies in the records/ folder beside the sweep's trials table."""
    if run.trials_file is None or not run.episode_files:
        return False
    sweep_records = (run.trials_file.parent / "records").resolve()
    return all(p.resolve().parent == sweep_records for p in run.episode_files)


def _provenance_section(run: RunData, out: Path, result: ReportResult) -> Section:
    provenance = report_provenance(run, out)
    result.files.append(_json(out / "provenance.json", provenance))
    counts = ReportTable("episode_counts", "Episode counts", "Episodes and errors per method as read from the records.",
                         episode_counts(run.episodes).astype(str), episode_counts(run.episodes))
    errors = ReportTable("error_messages", "Errors", "The commonest errors that ended episodes (each counts as a task failure).",
                         error_messages(run.episodes).astype(str), error_messages(run.episodes))
    items = [
        Preformatted("Report provenance (provenance.json)", to_json_text({k: v for k, v in provenance.items() if k != "run provenance"}), "json"),
        _table(counts, out, result),
        _table(errors, out, result),
    ]
    for name, value in run.provenance.items():
        items.append(Preformatted(f"Run provenance: {name}", to_json_text(value), "json"))
    for name, text in run.configs.items():
        items.append(Preformatted(f"Config: {name}", text, "yaml"))
    if not run.provenance and not run.configs:
        items.append("The run directory holds no config.yaml or provenance.json: the records' origin is not documented.")
    return Section("Provenance", items)


def _table(table: ReportTable, out: Path, result: ReportResult) -> ReportTable:
    result.tables.append(table)
    result.files.append(write_csv(table, out / "csv" / f"{table.key}.csv"))
    result.files.append(_write(out / "latex" / f"{table.key}.tex", table_latex(table)))
    return table


def _figure(key: str, title: str, caption: str, path: Path, result: ReportResult) -> ReportFigure:
    result.files.append(path)
    return ReportFigure(key, title, caption, path)


def _write(path: Path, text: str) -> Path:
    write_text_atomic(path, text)
    return path


def _json(path: Path, value: object) -> Path:
    write_json_atomic(path, value)
    return path
