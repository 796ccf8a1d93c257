"""The report in a real browser (Playwright driving Debian's headless Chromium, /usr/bin/chromium):
it loads from a file:// URL with no console error and no request that fails or leaves the file,
every figure decodes, the verdict is the first block and sits within the first screen on a phone
(390 x 844) and on a desktop (1280 x 800), the body never scrolls sideways, the parameter table
fits its box at both widths (no sideways scroll of its own: columns that wrap on the desktop, one
card per parameter on the phone), every figure is shown at a readable width, and a screenshot shows
the verdict box where the layout puts it; on the demo's kind of report and on a joint pixel fit's.
A crafted result's markup runs nothing."""

import io
import os
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = Path("/usr/bin/chromium")
ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
VIEWPORTS = {"phone": (390, 844), "desktop": (1280, 800)}
#: expected page height (px) per viewport: the page is long (figures), but not absurdly so
HEIGHT = {"phone": (2500, 12000), "desktop": (3000, 12000)}

# .ci/run installs the browser and sets VIBINVERSE_REQUIRE_BROWSER=1: there a missing browser fails
# the test instead of skipping it; on a plain machine it skips with one line
if os.environ.get("VIBINVERSE_REQUIRE_BROWSER") == "1":
    from playwright import sync_api

    assert CHROMIUM.exists(), "VIBINVERSE_REQUIRE_BROWSER=1 but there is no /usr/bin/chromium"
else:
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright not installed (pip install playwright)")
    pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason="no /usr/bin/chromium (apt-get install chromium)")


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """The report of the hand-made MCMC result (`test_report.hand_made_result`)."""
    from tests.vibinverse.test_report import hand_made_result
    from vibinverse.report import write_report

    d = tmp_path_factory.mktemp("browser")
    return write_report(hand_made_result(d / "result.nc"), d)


def open_page(browser, path, viewport):
    """(page, problems): the page loaded at `viewport`, and every console error, page error,
    failed request, request off file:// and data: URLs, and dialog seen while loading it."""
    w, h = viewport
    page = browser.new_page(viewport={"width": w, "height": h})
    page.set_default_timeout(30_000)
    problems = []
    page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
    page.on("requestfailed", lambda r: problems.append(f"request failed: {r.url[:80]} {r.failure}"))
    page.on(
        "request", lambda r: None if r.url.startswith(("file://", "data:")) else problems.append(f"network: {r.url}")
    )
    page.on("dialog", lambda d: (problems.append(f"dialog: {d.message}"), d.dismiss()))
    page.goto(path.resolve().as_uri(), wait_until="load")
    return page, problems


#: the verdict box's border colour by trust (vibinverse.report.CSS)
BORDER = {"yes": (0x2E, 0x7D, 0x32), "no": (0xC6, 0x28, 0x28), "unknown": (0xB7, 0x79, 0x1F)}


def check_page(browser, path, device, screenshot, n_images=None):
    """Every check of the module docstring on the report at `path` at `device`'s viewport; the
    full page's screenshot goes to `screenshot`. Returns the layout numbers."""
    from PIL import Image

    w, h = VIEWPORTS[device]
    page, problems = open_page(browser, path, (w, h))
    try:
        images = page.evaluate(
            "Array.from(document.images, i => [i.complete, i.naturalWidth, i.getBoundingClientRect().width])"
        )
        assert images and all(done and natural > 0 and shown <= w for done, natural, shown in images), images
        # every figure readable at its size: at least half the phone's width, 300 px on a desktop
        assert all(shown >= min(0.5 * w, 300) for _, _, shown in images), images
        assert n_images is None or len(images) == n_images
        assert page.evaluate("document.body.firstElementChild.id") == "verdict"
        box = page.locator("#verdict").bounding_box()
        assert box["y"] < 300 and box["y"] + box["height"] <= h, box  # the whole verdict on the first screen
        width = page.evaluate("document.documentElement.scrollWidth")
        assert width <= w  # no sideways scrolling of the page
        height = page.evaluate("document.documentElement.scrollHeight")
        assert HEIGHT[device][0] <= height <= HEIGHT[device][1], height
        # the parameter table needs no sideways scroll in its box, on the desktop as on the phone
        table = page.evaluate(
            "(e => [e.scrollWidth, e.clientWidth])(document.querySelector('#parameters .table-wrap'))"
        )
        assert table[0] <= table[1], table
        if device == "phone":  # one card per parameter, each cell labelled with its column
            labels = page.evaluate(
                "Array.from(document.querySelectorAll('#parameters td:not(.name)'), "
                "td => getComputedStyle(td, '::before').content)"
            )
            assert labels and all(label not in ("none", "", '""') for label in labels), labels
        shot = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), dtype=float)
        assert shot.shape[:2] == (h, w) and shot.var() > 0  # not blank
        # the verdict box where the layout puts it: its border, in the colour of its trust, on its
        # left edge at mid-height, and text inside it
        trust = page.evaluate("document.getElementById('verdict').classList[1]")
        x, y = round(box["x"] + 1), round(box["y"] + box["height"] / 2)
        assert np.abs(shot[y, x] - np.array(BORDER[trust])).max() < 40, (trust, shot[y, x])
        inside = shot[
            round(box["y"]) : round(box["y"] + box["height"]), round(box["x"]) : round(box["x"] + box["width"])
        ]
        assert inside.var() > 100
        page.screenshot(path=str(screenshot), full_page=True)
        numbers = {
            "viewport": f"{w}x{h}",
            "verdict_top": round(box["y"]),
            "verdict_height": round(box["height"]),
            "page": f"{width}x{height}",
            "parameter_table": f"{table[0]}/{table[1]}",
            "screenshot_variance": round(float(shot.var())),
            "trust": trust,
        }
        print(device, numbers)
    finally:
        page.close()
    assert problems == []
    return numbers


@pytest.mark.parametrize("device", list(VIEWPORTS))
def test_report_in_a_browser(browser, report, device, tmp_path):
    numbers = check_page(browser, report, device, tmp_path / f"report-{device}.png", n_images=6)
    assert numbers["trust"] == "yes"


@pytest.fixture(scope="module")
def pixel_report(tmp_path_factory):
    """The report of a joint fit of 64 pixels of one line, their gains a checkerboard of signs."""
    from tests.vibinverse.imaging.test_joint_fit import LINE, T, checkerboard, cube, line
    from vibinverse.imaging.joint_fit import fit_pixels
    from vibinverse.report import write_report

    rng = np.random.default_rng(6)
    y = 50.0 + np.outer(line(), checkerboard(64)) + rng.normal(0, 2.0, (T, 64))
    d = tmp_path_factory.mktemp("pixels")
    result = fit_pixels(cube(y), "all", LINE, method="map")
    return write_report(result.to_netcdf(d / "result.nc"), d)


@pytest.mark.parametrize("device", list(VIEWPORTS))
def test_a_joint_pixel_fit_report_in_a_browser(browser, pixel_report, device, tmp_path):
    """The same checks on a joint pixel fit's report, whose gain-and-sign map was once drawn a few
    pixels wide inside an empty frame."""
    assert "<h2>Pixels</h2><img" in pixel_report.read_text()  # the gain-and-sign map
    check_page(browser, pixel_report, device, tmp_path / f"pixels-{device}.png")


@pytest.mark.slow
def test_a_real_mcmc_report_in_a_browser(browser, tmp_path):
    """The same on the report of a real emcee fit (`vibinverse.api.fit(method="mcmc")`)."""
    from tests.vibinverse.test_report import real_mcmc_result
    from vibinverse.report import write_report

    path = write_report(real_mcmc_result(tmp_path / "result.nc"), tmp_path)
    for device in VIEWPORTS:
        check_page(browser, path, device, tmp_path / f"report-{device}.png")


def test_a_crafted_report_runs_nothing_in_a_browser(browser, tmp_path):
    """The hostile strings of `test_report._craft` in the hand-made result: no dialog, no element
    they would have made, no error."""
    from tests.vibinverse.test_report import _craft, hand_made_result
    from vibinverse.report import write_report

    src = hand_made_result(tmp_path / "result.nc", kind="laplace", walkers=2, draws=50)
    path = write_report(_craft(src, tmp_path / "crafted.nc"), tmp_path)
    page, problems = open_page(browser, path, VIEWPORTS["phone"])
    try:
        assert page.evaluate("document.querySelectorAll('script, img[src=\"x\"]').length") == 0
        assert "<script>alert(1)</script>" in page.inner_text("body")  # shown as text
        assert page.evaluate("document.documentElement.scrollWidth") <= VIEWPORTS["phone"][0]
    finally:
        page.close()
    assert problems == []
