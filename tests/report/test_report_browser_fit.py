"""The report on a laptop: at a 1,280 px window no table or figure is wider than the page, figures
keep legible text, and the Fig. 6 "All foods" row holds numbers (headless Chromium, `browser`)."""

from __future__ import annotations

import pytest

from grits_lab.report import build_report
from tests.report.chromium import open_chromium
from tests.report.synthetic_records import plausible_run

pytestmark = pytest.mark.browser

WINDOW = 1280
# Figures are scaled down to the page's column; at half their size and more, 7 pt labels drawn
# at 150 dpi stay at 7 px or more.
MIN_FIGURE_SCALE = 0.5


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    run = tmp_path_factory.mktemp("laptop")
    plausible_run(0, skip={"dp": ["fudge"]}).to_parquet(run / "episodes.parquet", index=False)
    report = build_report(run).out_dir / "report.html"
    driver = open_chromium(WINDOW)
    driver.get(report.resolve().as_uri())
    yield driver
    driver.quit()


def test_no_table_or_figure_is_wider_than_a_1280_pixel_window(page):
    assert page.execute_script("return window.innerWidth") == WINDOW
    assert page.execute_script("return document.documentElement.scrollWidth <= window.innerWidth")
    tables = page.execute_script(
        "return [...document.querySelectorAll('table')].map(t => ({rows: t.rows.length, width: t.scrollWidth, "
        "box: t.parentElement.clientWidth, right: t.getBoundingClientRect().right}))")
    assert len(tables) > 10
    too_wide = [t for t in tables if t["width"] > t["box"] or t["right"] > WINDOW]
    assert too_wide == []
    figures = page.execute_script(
        "return [...document.querySelectorAll('img')].map(i => ({alt: i.alt, natural: i.naturalWidth, "
        "shown: i.getBoundingClientRect().width, right: i.getBoundingClientRect().right}))")
    assert len(figures) >= 4
    for figure in figures:
        assert figure["right"] <= WINDOW and figure["shown"] >= MIN_FIGURE_SCALE * min(figure["natural"], WINDOW), figure


def test_the_all_foods_rows_hold_rates_not_dashes(page):
    rows = page.execute_script(
        "return [...document.querySelectorAll('tr')].filter(r => r.cells[0] && r.cells[0].textContent === 'All foods')"
        ".map(r => [...r.cells].map(c => c.textContent))")
    assert len(rows) == 2  # Diffusion Policy's and GRITS's parts of Fig. 6
    for cells in rows:
        assert "—" not in cells and all("%" in c for c in cells[2:]), cells
