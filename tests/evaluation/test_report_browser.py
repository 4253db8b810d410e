"""The report as people see it: report.html with replayed videos, opened in headless Chromium (Debian's chromium + chromium-driver).

Marked `browser` and out of the default run: `python -m pytest -m browser`. Skips with the reason
when Chromium, its driver or selenium is missing.
"""

from __future__ import annotations

from functools import partial

import pytest

from grits_lab.report.replay import replay_episode
from grits_lab.report import build_report
from grits_lab.sim.sim_config import CameraConfig
from tests.report.chromium import open_chromium

pytestmark = pytest.mark.browser

SMALL_CAMERA = CameraConfig(name="video", eye=(1.08, 0.14, 0.6), target=(0.47, 0.12, 0.07), fov_deg=50.0, width=160, height=120)


@pytest.fixture(scope="module")
def browser():
    driver = open_chromium(1400)
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def report_page(recorded_run, tmp_path_factory):
    run_dir, _ = recorded_run
    out = tmp_path_factory.mktemp("browser-report")
    build_report(run_dir, out, videos=1, replay=partial(replay_episode, camera=SMALL_CAMERA, every=4))
    return out / "report.html"


def test_every_figure_and_video_loads_without_a_console_error(browser, report_page):
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get(report_page.resolve().as_uri())
    n_videos = browser.execute_script("return document.querySelectorAll('video').length")
    assert n_videos == 2
    WebDriverWait(browser, 30).until(lambda d: d.execute_script(
        "return [...document.querySelectorAll('video')].every(v => v.readyState >= 1 || v.error)"))
    videos = browser.execute_script(
        "return [...document.querySelectorAll('video')].map(v => ({src: v.currentSrc, error: v.error && v.error.code, "
        "width: v.videoWidth, duration: v.duration}))")
    for video in videos:
        assert video["error"] is None and video["width"] == 160 and video["duration"] > 0, video
    images = browser.execute_script(
        "return [...document.querySelectorAll('img')].map(i => ({alt: i.alt, ok: i.complete && i.naturalWidth > 0}))")
    assert len(images) >= 4 and all(i["ok"] for i in images), images
    errors = [entry for entry in browser.get_log("browser") if entry["level"] == "SEVERE"]
    assert errors == []


def test_the_page_fits_a_1400_pixel_window_and_opens_with_the_headline(browser, report_page):
    browser.get(report_page.resolve().as_uri())
    fits = browser.execute_script("return document.documentElement.scrollWidth <= window.innerWidth")
    assert fits
    first_heading = browser.execute_script("return document.querySelector('section h2').textContent")
    assert first_heading == "Headline: Diffusion Policy vs GRITS"
    visible = browser.execute_script("return document.querySelector('section').getBoundingClientRect().top < window.innerHeight")
    assert visible
