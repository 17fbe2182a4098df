"""The view in a real browser: Debian's Chromium (installed by setup.sh) driven by Playwright.

The page is opened offline from a file:// URL, every other request is aborted and counted,
and the slider is moved with the mouse on its rail.
"""

from __future__ import annotations

import os

import pytest
from view_results import miura_result

from rffqm_nlp.show import view

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
#: Milliseconds allowed for plotly.js to load and draw (slow on a shared, software-rendered
#: machine).
LOAD_MS = 120_000
GD = "document.querySelector('.js-plotly-plot')"


@pytest.fixture(scope="module")
def browser():
    if not os.access(CHROMIUM, os.X_OK):
        pytest.fail(f"{CHROMIUM} not found: run setup.sh as root (it installs Debian's chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.fail("playwright is not installed: run setup.sh (the test extra)")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def x_of(page, trace: int) -> list:
    return page.evaluate(f"Array.from({GD}.data[{trace}].x)")


def wait_for_x(page, trace: int, want: list) -> None:
    """Wait until trace ``trace``'s x is ``want``: the slider's active index is set before
    its restyle has redrawn the data."""
    page.wait_for_function(
        f"([t, want]) => {{ const x = Array.from({GD}.data[t].x); "
        "return x.length === want.length && x.every((v, i) => v === want[i]); }",
        arg=[trace, want], timeout=LOAD_MS)


def click_step(page, index: int, count: int) -> None:
    """Click the slider rail above step ``index`` of ``count`` (its tick)."""
    ticks = page.locator(".slider-tick-rect")
    if ticks.count() == count:
        box = ticks.nth(index).bounding_box()
        x = box["x"] + box["width"] / 2
    else:  # ticks drawn in another way: spread the steps over the rail
        rail = page.locator(".slider-rail-rect").bounding_box()
        x = rail["x"] + rail["width"] * index / (count - 1)
    rail = page.locator(".slider-rail-touch-rect").bounding_box()
    page.mouse.click(x, rail["y"] + rail["height"] / 2)


def test_page_offline_and_slider_moves_geometry(browser, tmp_path):
    result = miura_result(8, omega=1.3)
    frames = 8
    path = view.write_html(result, tmp_path / "view.html", frames=frames)
    sp = view.spec(result, frames)
    steps = sp["layout"]["sliders"][0]["steps"]
    designed = next(n for n, s in enumerate(steps) if s["label"] == view.DESIGNED)

    page = browser.new_page()
    errors, console_errors, requests = [], [], []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on("console", lambda msg: console_errors.append(msg.text) if msg.type == "error"
            else None)

    def abort(route):
        requests.append(route.request.url)
        route.abort()

    page.route(lambda url: not url.startswith("file:"), abort)
    page.goto(path.resolve().as_uri())
    page.wait_for_selector(".slider-rail-touch-rect", timeout=LOAD_MS)
    page.wait_for_function(f"{GD} && {GD}._fullLayout !== undefined", timeout=LOAD_MS)

    assert page.evaluate(f"{GD}.data.length") == 5
    assert page.evaluate(f"{GD}._fullLayout.sliders[0].active") == designed
    assert x_of(page, 0) == steps[designed]["args"][0]["x"][0]

    click_step(page, 0, len(steps))
    page.wait_for_function(f"{GD}._fullLayout.sliders[0].active === 0", timeout=LOAD_MS)
    wait_for_x(page, 0, steps[0]["args"][0]["x"][0])
    assert x_of(page, 0) == steps[0]["args"][0]["x"][0] != steps[designed]["args"][0]["x"][0]
    assert x_of(page, 1) == steps[0]["args"][0]["x"][1]

    click_step(page, designed, len(steps))
    page.wait_for_function(f"{GD}._fullLayout.sliders[0].active === {designed}",
                           timeout=LOAD_MS)
    wait_for_x(page, 0, steps[designed]["args"][0]["x"][0])
    assert x_of(page, 0) == steps[designed]["args"][0]["x"][0]

    button = page.locator(".updatemenu-button").first
    button.click()
    page.wait_for_function(f"{GD}._fullData[4].visible === true", timeout=LOAD_MS)
    button.click()
    page.wait_for_function(f"{GD}._fullData[4].visible === false", timeout=LOAD_MS)

    page.close()
    assert errors == []
    assert console_errors == []
    assert requests == []
