"""The explorer's page in a real browser (headless Chromium of the system, driven by
Playwright): the page loaded with a URL state shows the headline chi that `index` gives
with the same --set values; a slider moved and released updates it to the value at the
new design; the URL round-trips (reload, back, forward); cancel stops a background job; a
bad value shows the command line's message next to its field and changes nothing.
No assertion depends on timing: the test waits for states of the page."""

from __future__ import annotations

import io
import os
import shutil
import urllib.request
from pathlib import Path
from urllib.parse import parse_qs, urlparse

import numpy as np
import pytest

from maglev_match import api
from maglev_match.core.params import load_params
from maglev_match.explore.server import ExploreServer

playwright_api = pytest.importorskip(
    "playwright.sync_api", reason="playwright is not installed (pip install -e '.[dev]')")

CHROMIUM = next((p for p in (shutil.which("chromium"), shutil.which("chromium-browser"),
                             "/usr/bin/chromium") if p and Path(p).exists()), None)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium found (the Debian "
                                "package chromium; .ci/run installs it in CI)")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
# ms: generous, the machine may be busy (EXPLORE_WAIT_MS to shorten it); nothing is timed
WAIT = int(os.environ.get("EXPLORE_WAIT_MS", "600000"))


@pytest.fixture(scope="module")
def server():
    s = ExploreServer("turnout-soft", "unit", port=0).start()
    yield s
    s.stop()


@pytest.fixture(scope="module")
def browser():
    with playwright_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


@pytest.fixture
def page(browser):
    pg = browser.new_page(viewport={"width": 1500, "height": 1000})
    yield pg
    pg.close()


def _base(server) -> str:
    return f"http://127.0.0.1:{server.port}/"


# Every predicate below reads its element with ?. : right after page.goto() the page may
# not have built it yet, and a predicate that throws ends the wait at once instead of
# waiting (seen once in CI: "Cannot read properties of null (reading 'textContent')").


def _settled(page) -> str:
    """Wait until the index shown is that of the page's latest release; its text."""
    page.wait_for_function(
        "() => document.getElementById('status')?.textContent === 'up to date'",
        timeout=WAIT)
    return page.locator("#chi").inner_text()


def _http(server, path: str) -> tuple[int, bytes]:
    with urllib.request.urlopen(f"http://127.0.0.1:{server.port}{path}", timeout=300) as r:
        return r.status, r.read()


def _index_chi(query: dict[str, list[str]]) -> str:
    """chi as `maglev-match index` prints its headline, to three decimals."""
    sets = {k: float(v[0]) for k, v in query.items() if k != "preset"}
    res = api.matching_index(query["preset"][0], stage=False, **sets)
    return f"{res.chi:.3f}"


def test_the_url_state_shows_the_index_of_the_command_line(server, page):
    page.goto(_base(server) + "?preset=turnout-soft&EI=2.2e10&kD=140")
    assert _settled(page) == _index_chi({"preset": ["turnout-soft"], "EI": ["2.2e10"],
                                         "kD": ["140"]})
    assert page.locator("#field-EI").input_value() == "2.2e+10"
    assert "--set EI=22000000000.0 --set kD=140.0" in page.locator("#cmdline").inner_text()


def test_a_released_slider_gives_the_index_there_and_the_url_round_trips(server, page):
    page.goto(_base(server) + "?preset=turnout-soft&kD=140")
    first = _settled(page)
    first_url = page.url
    page.locator("#slider-kD").fill("620")  # input + change: a move and its release
    page.wait_for_function("() => new URLSearchParams(location.search).get('kD') !== '140'",
                           timeout=WAIT)
    second = _settled(page)
    query = parse_qs(urlparse(page.url).query)
    assert set(query) == {"preset", "kD"}
    assert float(query["kD"][0]) == float(page.locator("#field-kD").input_value())
    assert second == _index_chi(query) != first
    # back: the earlier state and its index; forward: the new one again
    page.go_back()
    page.wait_for_function(f"() => location.href === {first_url!r}", timeout=WAIT)
    page.wait_for_function(f"() => document.getElementById('chi')?.textContent === "
                           f"{first!r}", timeout=WAIT)
    page.go_forward()
    page.wait_for_function(f"() => document.getElementById('chi')?.textContent === "
                           f"{second!r}", timeout=WAIT)
    # reload: the same state from the URL alone
    page.reload()
    assert _settled(page) == second


def test_cancel_stops_a_background_job(server, page):
    page.goto(_base(server) + "?preset=turnout-soft")
    _settled(page)
    # the curve the release started is drawn first (so that the job cancelled below is
    # the one started here); the new job may wait behind the map tile, then runs
    page.wait_for_function("() => ['done', 'error'].includes(document.getElementById("
                           "'job-status')?.dataset.status)", timeout=WAIT)
    page.locator("#job-start").click()
    page.wait_for_function("() => document.getElementById('job-status')?.dataset.status === "
                           "'running'", timeout=WAIT)
    page.locator("#job-cancel").click()
    page.wait_for_function("() => document.getElementById('job-status')?.dataset.status === "
                           "'cancelled'", timeout=WAIT)
    # the process that ran it has ended (a job waiting behind it starts a fresh one)
    job = server.jobs.job(page.evaluate("() => JOBS.hopf_curve.job.id"))
    assert job.status == "cancelled" and not job.process.is_alive()
    # the next job runs to its end and draws the curve
    page.locator("#job-start").click()
    page.wait_for_function("() => document.getElementById('job-status')?.dataset.status === "
                           "'done'", timeout=WAIT)


def test_a_bad_value_shows_the_message_and_changes_nothing(server, page):
    page.goto(_base(server) + "?preset=turnout-soft&kD=140")
    chi = _settled(page)
    url = page.url
    field = page.locator("#field-kD")
    field.fill("-5")
    field.press("Enter")
    field.blur()
    page.wait_for_function("() => (document.getElementById('err-kD')?.textContent ?? '') "
                           "!== ''",
                           timeout=WAIT)
    assert page.locator("#err-kD").inner_text() == "parameter 'kD' = -5.0: must be >= 0"
    assert page.url == url and page.locator("#chi").inner_text() == chi
    # a bad value in the URL: refused the same way, nothing computed
    page.goto(_base(server) + "?preset=turnout-soft&EI=inf")
    page.wait_for_function("() => (document.getElementById('err-EI')?.textContent ?? '') "
                           "!== ''",
                           timeout=WAIT)
    assert "must be a finite number" in page.locator("#err-EI").inner_text()
    assert page.locator("#chi").inner_text() == "–"


def _job_done(page, prefix: str) -> None:
    page.wait_for_function(f"() => document.getElementById('{prefix}-status')?.dataset.status "
                           "=== 'done'", timeout=WAIT)


def _move(page, name: str, k: int) -> None:
    """Move a slider to step k without letting it go (input, no change)."""
    page.locator(f"#slider-{name}").evaluate(
        f"(el) => {{ el.value = '{k}'; el.dispatchEvent(new Event('input')); }}")


def test_a_moving_slider_shows_chi_interpolated_from_the_map_tile(server, page):
    import xarray as xr

    page.goto(_base(server) + "?preset=turnout-soft&EI=2.2e10&kD=140")
    _settled(page)
    _job_done(page, "tile")  # started by the release: the design lies on no tile yet
    tile = server.jobs.latest("tile").result
    design = load_params("turnout-soft", None, {"EI": 2.2e10, "kD": 140.0})
    # the tile is centred on the design; its centre is the index at the design
    assert tile["x"][2] == pytest.approx(design.omega1, rel=1e-12)
    assert tile["y"][2] == pytest.approx(design.sigma, rel=1e-12)
    exact = float(page.locator("#chi").get_attribute("data-value"))
    assert tile["chi"][2][2] == pytest.approx(exact, rel=2e-2)
    # the tile as netCDF: the map's dataset, the same numbers
    code, data = _http(server, "/api/export/netcdf?what=tile")
    ds = xr.open_dataset(io.BytesIO(data), engine="h5netcdf")
    assert code == 200 and np.allclose(ds["chi"].values, np.array(tile["chi"], float),
                                       equal_nan=True)
    # EI moves (omega1 with it): chi interpolated, marked so, between the tile's values
    _move(page, "EI", 530)
    page.wait_for_function("() => document.getElementById('chi-mark')?.textContent"
                           ".includes('interpolated')", timeout=WAIT)
    assert page.locator("#chi-interp").get_attribute("data-state") == "interpolated"
    assert "interpolated" in page.locator("#chi-interp").inner_text()
    value = float(page.locator("#chi-interp").get_attribute("data-value"))
    w = design.omega1 * (float(page.locator("#field-EI").input_value()) / 2.2e10) ** 0.5
    i = int(np.searchsorted(tile["x"], w)) - 1
    cells = [tile["chi"][j][k] for j in (2, 3) for k in (i, i + 1)]
    assert tile["x"][i] < w < tile["x"][i + 1]
    assert min(cells) <= value <= max(cells)
    # a gain moves: the tile does not hold it, no number
    page.locator("#slider-EI").dispatch_event("change")
    _settled(page)
    _move(page, "kD", 300)
    page.wait_for_function("() => document.getElementById('chi-interp')?.textContent"
                           ".startsWith('no tile here')", timeout=WAIT)
    assert page.locator("#chi-interp").get_attribute("data-state") == "none"


def test_the_speed_sweep_shows_chi_at_speed_beside_the_standstill_headline(server, page):
    page.goto(_base(server) + "?preset=turnout-soft&kD=140&v=60")
    chi = _settled(page)
    _job_done(page, "speed")
    assert float(page.locator("#chi-v").get_attribute("data-value")) > 0
    assert "at 60 km/h" in page.locator("#chi-v").inner_text()
    # the sweep's own standstill headline is the index the page released
    assert page.locator("#chi-0").inner_text() == chi
    assert parse_qs(urlparse(page.url).query)["v"] == ["60"]
    # a speed that is refused: the rule next to the field, no job started
    field = page.locator("#field-v")
    field.fill("-3")
    field.press("Enter")
    page.wait_for_function("() => (document.getElementById('err-v')?.textContent ?? '') "
                           "!== ''",
                           timeout=WAIT)
    assert page.locator("#err-v").inner_text() == ("parameter 'v' = -3.0: must be 0 "
                                                   "(standstill) or from 3 to 900 km/h")
