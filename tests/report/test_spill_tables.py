"""The report's account of where food was lost: the stage x cause table, delivery after the scoop, the replay caption."""

from __future__ import annotations

import pandas as pd

from grits_lab.report.replay import attribution_caption
from grits_lab.report.run_records import normalize_records
from grits_lab.report.spill_tables import delivery_table, spill_attribution_table
from grits_lab.report.tables import failure_table
from grits_lab.sim.spill_metrics import attribution_columns
from tests.report.synthetic_records import episode


def _run(rows: list[tuple[str, str, int, int, dict[str, int]]]) -> pd.DataFrame:
    """Records from (method, food, scooped, transferred, {attribution column: particles})."""
    records = []
    for i, (method, food, scooped, transferred, lost) in enumerate(rows):
        row = episode(method, food, "low", i, "success")
        row.update({c: 0 for c in attribution_columns()})
        row.update(lost)
        after = sum(n for c, n in lost.items() if not c.startswith("spilled_scoop_"))
        row.update({"scooped": scooped, "transferred": transferred, "above_spoon_rim": 2, "spilled_transfer": after,
                    "spilled": sum(lost.values()) - after, "spillage": sum(lost.values()) > after,
                    "task_success": not lost and transferred * 2 >= scooped})
        records.append(row)
    return normalize_records(pd.DataFrame(records))


def test_each_stage_with_a_spill_is_a_row_with_episodes_and_particles_per_cause():
    run = _run([("dp", "sago", 20, 18, {"spilled_carry_off_spoon": 2}),
                ("dp", "sago", 20, 15, {"spilled_carry_off_spoon": 1, "spilled_pour_poured_outside": 4}),
                ("dp", "penne", 10, 10, {}),
                ("dp", "penne", 10, 0, {"spilled_scoop_over_rim": 3})])
    table = spill_attribution_table(run)
    shown = table.display.set_index("Stage")
    assert list(shown.index) == ["Scoop", "Carry", "Pour"]
    assert shown.loc["Carry", "Off the moving spoon"] == "2/4 (3)"
    assert shown.loc["Pour", "Poured outside the target"] == "1/4 (4)"
    assert shown.loc["Scoop", "Over the source rim"] == "1/4 (3)" and shown.loc["Carry", "Any cause"] == "2/4"
    data = table.data.set_index(["stage", "cause"])
    assert data.loc[("carry", "off_spoon"), "particles"] == 3 and data.loc[("lift", "off_spoon"), "episodes_k"] == 0


def test_delivery_counts_episodes_that_bring_90_percent_of_the_load_and_spill_nothing_after_the_scoop():
    run = _run([("expert", "sago", 20, 20, {}),                                  # delivered
                ("expert", "sago", 20, 17, {}),                                  # 85 %: short
                ("expert", "penne", 10, 10, {"spilled_after_pour_bounced_out": 1}),  # all in, one bounced out
                ("expert", "penne", 0, 0, {})])                                  # lifted nothing: not counted
    table = delivery_table(run)
    overall = table.data.iloc[0]
    assert (overall["food"], overall["episodes"], overall["delivered_k"], overall["spill_after_scoop_k"]) == ("All foods", 3, 1, 1)
    per_food = table.data.iloc[1:].set_index("food")  # one method: its rows per food and level follow
    assert per_food.loc["PE penne", "episodes"] == 1 and per_food.loc["SA sago", "delivered_k"] == 1


def test_the_delivery_table_sums_where_the_lifted_load_ended():
    run = _run([("expert", "sago", 20, 17, {}), ("expert", "sago", 10, 10, {})])
    run["lifted_delivered"], run["lifted_in_spoon"], run["lifted_in_source"] = [17, 10], [1, 0], [2, 0]
    run["lifted_spilled"], run["lifted_elsewhere"] = [0, 0], [0, 0]
    table = delivery_table(run)
    overall = table.data.iloc[0]
    assert (overall["lifted_delivered"], overall["lifted_in_spoon"], overall["lifted_in_source"]) == (27, 1, 2)
    assert table.display.iloc[0]["Lifted: delivered / in spoon / in source / spilled / elsewhere"] == "27 / 1 / 2 / 0 / 0"
    older = delivery_table(_run([("expert", "sago", 20, 17, {})]))  # records before the columns existed
    assert older.display.iloc[0]["Lifted: delivered / in spoon / in source / spilled / elsewhere"] == "—"


def test_the_failure_table_splits_the_spills_after_the_scoop_by_stage():
    run = _run([("dp", "sago", 20, 18, {"spilled_carry_off_spoon": 2}),
                ("dp", "sago", 20, 15, {"spilled_lift_off_spoon": 1, "spilled_pour_poured_outside": 4}),
                ("dp", "penne", 10, 10, {})])
    row = failure_table(run).data.iloc[0]
    assert (row["spill_lift_k"], row["spill_carry_k"], row["spill_pour_k"], row["spill_after_pour_k"]) == (1, 1, 1, 0)


def test_records_without_the_attribution_give_an_empty_table_that_says_so():
    records = normalize_records(pd.DataFrame([episode("dp", "sago", "low", 0, "success")]))
    table = spill_attribution_table(records)
    assert table.display.empty and "predate" in table.notes[0]
    assert delivery_table(records).data.empty


def test_the_replay_caption_names_stage_cause_and_count_of_what_was_lost():
    lost = {c: 0 for c in attribution_columns()}
    assert attribution_caption(lost) == ""
    lost.update({"spilled_carry_off_spoon": 2, "spilled_pour_poured_outside": 1})
    assert attribution_caption(lost) == "lost: carry, off the moving spoon 2 · pour, poured outside the target 1"


def test_the_load_loss_figure_is_drawn_from_the_records_and_skipped_without_them(tmp_path):
    from grits_lab.report.spill_tables import load_loss_figure

    run = _run([("dp", "sago", 20, 18, {"spilled_carry_off_spoon": 2}), ("dp", "penne", 10, 10, {})])
    assert load_loss_figure(run, tmp_path / "loss.png") == tmp_path / "loss.png" and (tmp_path / "loss.png").stat().st_size > 0
    bare = normalize_records(pd.DataFrame([episode("dp", "sago", "low", 0, "success")]))
    assert load_loss_figure(bare, tmp_path / "none.png") is None and not (tmp_path / "none.png").exists()


def test_every_replay_frame_has_the_same_caption_height_whether_or_not_food_was_lost(monkeypatch):
    """A video's frames must share one size: the caption keeps its line for what was lost even
    before anything was (the renderer is replaced by a blank frame: only the caption is under test)."""
    import numpy as np

    import grits_lab.sim.video as video
    from grits_lab.report.replay import _FilmedEnv

    class Episode:
        tracker = type("Tracker", (), {"stage": "carry"})()
        lost = {c: 0 for c in attribution_columns()}

        def metrics(self):
            return {"spill_attribution": dict(self.lost)}

    monkeypatch.setattr(video, "render_frame", lambda env, camera: np.zeros((40, 60, 3), np.uint8))
    episode_env = Episode()
    filmed = _FilmedEnv(episode_env, "dp sago/low trial 0", camera=None, every=1)
    filmed._film({"step": 0, "spilled": 0})
    episode_env.lost["spilled_carry_off_spoon"] = 2
    filmed._film({"step": 1, "spilled": 2})
    assert filmed.frames[0].shape == filmed.frames[1].shape
