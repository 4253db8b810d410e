"""The report page's layout (headline first, missing cells collapsed, wide tables in their own box) and the video rule."""

from __future__ import annotations

import re
from types import SimpleNamespace

import pandas as pd
import numpy as np
import pytest

from grits_lab.report import build_report, normalize_records
from grits_lab.report.videos import choose_episodes, film_picks
from tests.report.synthetic_records import episode, plausible_run


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    run = tmp_path_factory.mktemp("layout")
    plausible_run(0, skip={"dp": ["fudge"]}).to_parquet(run / "episodes.parquet", index=False)
    result = build_report(run)
    return result, (result.out_dir / "report.html").read_text()


def test_the_page_opens_with_the_headline_comparison_with_counts(page):
    result, html = page
    frame = plausible_run(0, skip={"dp": ["fudge"]})
    body = html.split("</nav>", 1)[1]
    first_section = body.split("</section>", 1)[0]
    assert "Headline: Diffusion Policy vs GRITS" in first_section
    for method in ("dp", "grits"):
        rows = frame[frame["method"] == method]
        k, n = int(rows["spillage"].sum()), len(rows)
        assert f"({k}/{n})" in first_section and f"spilled in {k} of {n} episodes" in first_section
    headline = next(t for t in result.tables if t.key == "headline")
    assert list(headline.display.columns) == ["Method", "Episodes", "Task success", "Spillage", "Scoop failure"]


def test_missing_cells_are_listed_only_inside_collapsed_details(page):
    result, html = page
    assert result.missing  # DP has no fudge episodes
    outside = re.sub(r"<details.*?</details>", "", html, flags=re.S)
    assert "Missing (no episode records)" not in outside and "Missing" in html
    overview = html.split('<h2>Overview</h2>', 1)[1].split("</section>", 1)[0]
    assert "<details class=missing><summary>Missing data:" in overview


def test_every_table_sits_in_its_own_scrolling_box(page):
    _, html = page
    tables = html.count('<table')
    assert tables > 5 and html.count('<div class="scroll"><table') == tables
    assert re.search(r"div\.scroll\{[^}]*overflow-x:auto", html)


def test_a_plain_report_replays_nothing(page):
    result, html = page
    assert "<video" not in html and not (result.out_dir / "videos").exists()


def picks_for(rows: list[dict], per_food: int) -> list:
    return choose_episodes(normalize_records(pd.DataFrame(rows)), per_food)


def test_videos_prefer_the_seed_where_dp_spilled_and_grits_did_not():
    rows = []
    outcomes = {0: ("success", "success"), 1: ("spill", "spill"), 2: ("spill", "success"), 3: ("success", "spill")}
    for trial, (dp, grits) in outcomes.items():
        rows += [episode("dp", "sago", "low", trial, dp), episode("grits", "sago", "low", trial, grits)]
    picks = picks_for(rows, 4)
    assert [p.trial for p in picks] == [2, 1, 3, 0]
    assert picks[0].methods == ["dp", "grits"] and picks[0].reason == "Diffusion Policy spilled, GRITS did not"
    assert [p.trial for p in picks_for(rows, 1)] == [2]


def test_videos_break_ties_by_level_then_trial_and_skip_errored_episodes():
    rows = []
    for level in ("high", "low"):
        for trial in (1, 0):
            rows += [episode("dp", "penne", level, trial, "spill", error="sim crashed" if (level, trial) == ("low", 0) else ""),
                     episode("grits", "penne", level, trial, "success")]
    assert [(p.level, p.trial) for p in picks_for(rows, 3)] == [("low", 1), ("high", 0), ("high", 1)]


def test_a_food_recorded_for_one_method_only_shows_that_method():
    rows = [episode("grits", "fudge", "low", t, "spill" if t == 1 else "success") for t in range(3)]
    picks = picks_for(rows, 1)
    assert len(picks) == 1 and picks[0].methods == ["grits"] and picks[0].trial == 1


def test_a_replay_that_cannot_run_is_shown_with_its_reason(tmp_path, capsys):
    from grits_lab.errors import StorageError

    def replay(run_dir, *, method, food, level, trial, video):
        if method == "dp":
            raise StorageError("checkpoint `policy` changed")
        video.parent.mkdir(parents=True, exist_ok=True)
        video.write_bytes(b"")
        return SimpleNamespace(replayed={"task_success": True, "spilled_total": 0, "scoop_success": True},
                               describe=lambda: "replay reproduces the record")

    rows = [episode("dp", "sago", "low", 0, "spill"), episode("grits", "sago", "low", 0, "success")]
    [row] = film_picks(tmp_path, picks_for(rows, 1), replay, tmp_path, progress=True)
    dp, grits = row.videos
    assert dp.path is None and "checkpoint `policy` changed" in dp.caption
    assert grits.path == "videos/sago-low-0-grits.mp4" and "reproduces" in grits.caption
    final = capsys.readouterr().err.replace("\r", "\n").strip().splitlines()[-1]
    assert final.startswith("replaying episodes") and "2/2" in final  # one tick per video, failed ones too


def test_guidance_distributions_per_method_from_the_records(tmp_path):
    from grits_lab.report.guidance_effect import guided_episodes

    frame = plausible_run(1)
    guided = frame["method"].isin(["grits", "dp_post"])
    frame["guided_steps"] = guided.astype(int) * 6
    frame["p_spill_before"] = frame["trial"].map({0: 0.2, 1: 0.4, 2: 0.6, 3: 0.8, 4: 0.9}).where(guided)
    frame["p_spill_after"] = (frame["p_spill_before"] - 0.1).where(guided)
    frame["guidance_displacement"] = 0.5
    frame.loc[frame["trial"] == 4, "p_spill_after"] = 0.95  # guidance raised it once per (food, level)
    frame.to_parquet(tmp_path / "episodes.parquet", index=False)
    result = build_report(tmp_path)
    table = next(t for t in result.tables if t.key == "guidance")
    assert list(table.data["variant"]) == ["dp_post", "grits"]  # dp and the rest have no guided steps
    grits = table.data.set_index("variant").loc["grits"]
    errors = int(normalize_records(frame).query("method == 'grits'")["is_error"].sum())
    assert grits["episodes"] == 100 - errors and grits["p_spill_before_median"] == pytest.approx(0.6)
    assert grits["lowered"] == len(guided_episodes(normalize_records(frame)).query("method == 'grits' and trial != 4"))
    assert (result.out_dir / "figures" / "guidance.png").stat().st_size > 0
    assert "Guidance: what it changed" in (result.out_dir / "report.html").read_text()


def test_guidance_reads_the_unguided_comparison_per_plan_when_recorded(tmp_path):
    frame = plausible_run(1)
    guided = frame["method"] == "grits"
    frame["guided_steps"] = guided.astype(int) * 6
    for column in ("p_spill_before", "p_spill_after", "guidance_displacement"):
        frame[column] = np.where(guided, 0.5, np.nan)
    frame["p_spill_unguided"] = np.where(guided, 0.3, np.nan)
    frame["p_spill_guided"] = np.where(guided, 0.2, np.nan)
    frame["guidance_displacement_mm"] = np.where(guided, 4.0, np.nan)
    # Two plans per episode: guidance lowered P(spill) in the first and raised it in the second.
    frame["plan_p_spill_unguided"] = [[0.4, 0.2] if g else None for g in guided]
    frame["plan_p_spill_guided"] = [[0.1, 0.3] if g else None for g in guided]
    frame.to_parquet(tmp_path / "episodes.parquet", index=False)
    table = next(t for t in build_report(tmp_path).tables if t.key == "guidance")
    grits = table.data.set_index("variant").loc["grits"]
    assert grits["p_spill_before_median"] == pytest.approx(0.3) and grits["p_spill_after_median"] == pytest.approx(0.2)
    assert grits["guidance_displacement_median"] == pytest.approx(4.0)
    assert grits["plans"] == 2 * grits["episodes"] and grits["plans_lowered"] == grits["episodes"]


def test_guidance_by_plan_index_shows_where_in_the_scoop_guidance_acts(tmp_path):
    frame = plausible_run(1)
    guided = frame["method"] == "grits"
    frame["guided_steps"] = guided.astype(int) * 6
    for column in ("p_spill_before", "p_spill_after", "guidance_displacement", "p_spill_unguided", "p_spill_guided",
                   "guidance_displacement_mm"):
        frame[column] = np.where(guided, 0.5, np.nan)
    # Three plans per episode: guidance barely moves the first, then pushes harder as P(spill) rises.
    frame["plan_p_spill_unguided"] = [[0.01, 0.3, 0.2] if g else None for g in guided]
    frame["plan_p_spill_guided"] = [[0.01, 0.2, 0.15] if g else None for g in guided]
    frame["plan_displacement_mm"] = [[0.2, 9.0, 6.0] if g else None for g in guided]
    frame.to_parquet(tmp_path / "episodes.parquet", index=False)
    result = build_report(tmp_path)
    table = next(t for t in result.tables if t.key == "guidance_by_plan")
    grits = table.data.set_index("plan")
    assert list(grits.index) == [0, 1, 2] and set(table.data["variant"]) == {"grits"}
    assert grits.loc[1, "displacement_mm_median"] == pytest.approx(9.0) and grits.loc[0, "p_spill_unguided_median"] == pytest.approx(0.01)
    assert (grits["plans"] == grits.loc[0, "plans"]).all() and grits.loc[0, "plans"] > 0
    assert "Guidance by plan index" in (result.out_dir / "report.html").read_text()


def test_the_all_foods_row_pools_every_food_of_the_method():
    from grits_lab.report.tables import per_food_table

    rows = [episode("grits", "sago", "low", i, "success" if i < 3 else "spill") for i in range(5)]
    rows += [episode("grits", "fudge", "low", i, "success") for i in range(3)]
    parts = dict(per_food_table(normalize_records(pd.DataFrame(rows))).parts)
    pooled = parts["GRITS"].set_index("Food").loc["All foods"]
    assert pooled["Episodes"] == "8"
    assert pooled["Success"] == "75.0% [40.9, 92.9] (6/8)" and pooled["Spillage (before scoop)"] == "25.0% [7.1, 59.1] (2/8)"
    assert parts["Diffusion Policy"].set_index("Food").loc["All foods", "Success"] == "—"  # no DP records at all


def test_every_rate_is_rounded_one_way_halves_up():
    from grits_lab.intervals import format_percent, format_rate, rate
    from grits_lab.report.headline import headline_table

    assert format_percent(5 / 8) == "62.5%" and format_percent(1 / 16) == "6.3%" and format_percent(0.145) == "14.5%"
    rows = [episode("grits", "sago", "low", i, "success" if i < 5 else "spill") for i in range(8)]
    headline = headline_table(normalize_records(pd.DataFrame(rows))).display.set_index("Method")
    assert headline.loc["GRITS", "Task success"] == format_rate(rate(5, 8)) == "62.5% [30.6, 86.3] (5/8)"
    assert format_rate(rate(5, 8)).startswith("62.5% [")


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_breakdown_heatmap_titles_do_not_overlap_with_two_methods():
    from grits_lab.report import figures
    from grits_lab.report.tables import all_variants, breakdown_tables

    rows = [episode(m, "sago", lv, i, "success") for m in ("dp", "grits") for lv in ("low", "high") for i in range(2)]
    records = normalize_records(pd.DataFrame(rows))
    wide = {t.key.removeprefix("breakdown_"): t.data for t in breakdown_tables(records)}
    fig = figures.breakdown_heatmap_figure(wide, all_variants(records))
    renderer = fig.canvas.get_renderer()
    fig.canvas.draw()
    titles = [ax.title.get_window_extent(renderer) for ax in fig.axes] + [fig._suptitle.get_window_extent(renderer)]
    assert len(titles) == 4
    assert not any(_overlap(a, b) for i, a in enumerate(titles) for b in titles[i + 1:])


def test_fig5_labels_sit_clear_of_the_papers_diamonds():
    from grits_lab.report import figures
    from grits_lab.report.tables import method_table
    from grits_lab.report.vocabulary import MAIN_METHODS

    # GRITS at 7/12 task success: the interval ends at 80.7 %, just under the paper's 82 % diamond,
    # where a label drawn right above the error bar would sit under the diamond.
    rows = [episode("grits", "sago", "low", i, "success" if i < 7 else "spill") for i in range(12)]
    table = method_table(normalize_records(pd.DataFrame(rows)), MAIN_METHODS, "fig5", "Fig. 5", "")
    fig = figures.method_bars_figure(table.data, "Fig. 5")
    fig.canvas.draw()
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    labels = [t for t in ax.texts if t.get_text()[:1].isdigit()]
    diamonds = [line for line in ax.lines if line.get_marker() == "D"]
    assert {t.get_text() for t in labels} == {"58.3", "41.7", "0.0"} and len(diamonds) == 3
    for diamond in diamonds:
        box = diamond.get_window_extent(renderer)
        assert not any(_overlap(box, t.get_window_extent(renderer)) for t in labels)


def test_the_training_section_shows_each_runs_curves_and_last_values(tmp_path):
    from grits_lab.training import MetricLogger

    plausible_run(0).to_parquet(tmp_path / "episodes.parquet", index=False)
    for name, metrics in {"policy": {"train_loss": 0.5, "lr": 1e-4, "val_loss": 0.6},
                          "predictor/predictor": {"train_loss": 0.4, "lr": 1e-3, "val_auroc": 0.74}}.items():
        logger = MetricLogger(tmp_path / "train" / name, namespace=name.split("/")[0], tensorboard=False)
        logger.log(1, metrics)
        logger.close()
    result = build_report(tmp_path, tmp_path / "report", training=[tmp_path / "train" / "policy", tmp_path / "train" / "predictor"])
    html = (result.out_dir / "report.html").read_text()
    section = html.split("<h2>Training</h2>", 1)[1].split("</section>", 1)[0]
    assert section.count("<img") == 2 and "val_auroc 0.74" in section and "val_loss 0.6" in section
    assert (result.out_dir / "figures" / "training_predictor_predictor.png").is_file()
    assert "<h2>Training</h2>" not in (build_report(tmp_path, tmp_path / "plain").out_dir / "report.html").read_text()


def test_a_labs_own_methods_never_wear_a_built_in_methods_colour():
    from matplotlib.colors import to_rgb

    from grits_lab.report import figures
    from grits_lab.report.tables import method_table
    from grits_lab.report.vocabulary import MAIN_METHODS

    # Fig. 5 lists the six main methods, then the records' other methods: torch_mlp sits at row 6,
    # where a colour chosen by row was dp_post's brown.
    rows = [episode(m, "sago", "low", i, "success") for m in ("dp_post", "torch_mlp", "lab_policy") for i in range(2)]
    table = method_table(normalize_records(pd.DataFrame(rows)), MAIN_METHODS, "fig5", "Fig. 5", "", extra=True)
    fig = figures.method_bars_figure(table.data, "Fig. 5")
    handles, labels = fig.axes[0].get_legend_handles_labels()
    colour = {label.rsplit(" (n=", 1)[0]: to_rgb(h.patches[0].get_facecolor()) for h, label in zip(handles, labels) if "(n=" in label}
    built_in = {to_rgb(c) for c in figures.METHOD_COLORS.values()}
    assert set(colour) == {"Diffusion Policy (Post.)", "torch_mlp", "lab_policy"}
    assert colour["torch_mlp"] not in built_in and colour["lab_policy"] not in built_in
    assert colour["torch_mlp"] != colour["lab_policy"]
