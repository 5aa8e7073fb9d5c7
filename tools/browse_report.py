"""Open a Snakemake report in headless Chromium as a reader would, click every category and every
result, and list what a reader could not see.

Debian's `chromium` and `chromium-driver` (tools/setup.sh installs both), driven by Selenium with
the driver's path given, so nothing is downloaded. A problem is reported when:
- the findings category is missing, or is not the first category of the menu;
- a result shows nothing (no image, or an empty HTML page);
- a figure is cropped by the viewer (any edge of the image outside the visible content area) or
  shown smaller than its pixels (the viewer scales down an image wider than its pane: its text
  would shrink below the size it was drawn at);
- an HTML table is wider than its frame (a horizontal scroll bar hides columns), or a word of
  one of its cells is broken across lines (a long identifier may break between its parts,
  `tacgen_lib.report.tables.cell_html`; a monospaced hash or path column anywhere);
- a result has no caption, or a caption that is only its file name.

    usage: python tools/browse_report.py results/report.html [--shots DIR] [--size 1600x1000]
"""

from __future__ import annotations

import argparse
import contextlib
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tacgen_lib.report_pages import page_of  # noqa: E402

FINDINGS = "Findings"

CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)


@dataclass
class Visit:
    """What one result looked like in the viewer."""

    category: str
    subcategory: str
    name: str
    kind: str
    problems: list[str] = field(default_factory=list)
    shot: str = ""


def find_browser() -> tuple[str, str]:
    """(chromium, chromedriver) paths; RuntimeError naming what is missing."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if not chromium or not driver:
        raise RuntimeError(
            "headless Chromium is not installed (Debian packages chromium and chromium-driver): "
            "run tools/setup.sh"
        )
    return chromium, driver


@contextlib.contextmanager
def chromium(width: int, height: int) -> Iterator[object]:
    """A headless Chromium whose page viewport is exactly width × height CSS pixels."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    binary, driver_path = find_browser()
    profile = tempfile.mkdtemp(prefix="tacgen-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = binary
    for flag in CHROMIUM_FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={profile}")
    opts.add_argument(f"--window-size={width},{height}")
    driver = webdriver.Chrome(service=Service(driver_path), options=opts)
    try:
        # the window size includes no browser chrome in headless mode, but make sure
        inner = driver.execute_script("return [window.innerWidth, window.innerHeight]")
        if inner != [width, height]:
            driver.set_window_size(2 * width - inner[0], 2 * height - inner[1])
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def _menu_labels(driver) -> list[str]:
    """The visible labels of the menu's links (one script: a WebDriver call per element costs
    a round trip to the browser each, ~20 ms on a loaded 2-core machine)."""
    return driver.execute_script(
        "return [...document.querySelectorAll('nav a > span, #menu a > span, ul a > span')]"
        ".map(s => s.innerText).filter(t => t)"
    )


def _click_text(driver, text: str) -> None:
    for el in driver.find_elements("xpath", f"//a[span[normalize-space(text())='{text}']]"):
        if el.is_displayed():
            el.click()
            return
    raise LookupError(f"no visible link {text!r}")


# Geometry of what is shown in the content pane (the viewer's right-hand side).
_IMAGE_GEOMETRY = """
const img = document.querySelector('.h-screen.overflow-auto > div.p-3 > img');
if (!img) { return null; }
const pane = img.closest('.overflow-auto') || document.documentElement;
const r = img.getBoundingClientRect(), p = pane.getBoundingClientRect();
return {natural: [img.naturalWidth, img.naturalHeight], shown: [r.width, r.height],
        img: [r.left, r.top, r.right, r.bottom], pane: [p.left, p.top, p.right, p.bottom],
        viewport: [window.innerWidth, window.innerHeight]};
"""

_FRAME_GEOMETRY = """
const d = document;
if (!d.body) { return {empty: true}; }
// words of table cells laid out on more than one line: broken mid-word (a text node is a run
// between two line-break opportunities the page allows, <wbr>)
const broken = [];
for (const cell of d.querySelectorAll('td:not(.mono), th')) {
  const walk = d.createTreeWalker(cell, NodeFilter.SHOW_TEXT);
  for (let node = walk.nextNode(); node; node = walk.nextNode()) {
    for (const m of node.data.matchAll(/[^\\s\\-–]+[\\-–]?/g)) {
      const r = d.createRange();
      r.setStart(node, m.index);
      r.setEnd(node, m.index + m[0].length);
      const tops = new Set([...r.getClientRects()].map((x) => Math.round(x.top)));
      if (tops.size > 1) { broken.push(m[0]); }
    }
  }
}
return {empty: d.body.innerText.trim().length === 0,
        scroll: [d.documentElement.scrollWidth, d.documentElement.clientWidth],
        broken: broken.slice(0, 5),
        text: d.body.innerText.slice(0, 200)};
"""


def check_image(geometry: dict | None) -> list[str]:
    """Problems of a figure from its geometry in the viewer (see `_IMAGE_GEOMETRY`)."""
    if geometry is None:
        return ["shows nothing: no image in the viewer"]
    problems = []
    (nw, nh), (sw, _) = geometry["natural"], geometry["shown"]
    left, top, right, bottom = geometry["img"]
    pl, pt, pr, pb = geometry["pane"]
    if nw == 0 or nh == 0:
        problems.append("shows nothing: the image has no pixels")
    if sw < nw - 1:
        problems.append(f"shown at {sw / nw:.0%} of its {nw}×{nh} px: wider than the viewer")
    if top < pt - 1 or bottom > min(pb, geometry["viewport"][1]) + 1:
        problems.append(
            f"cropped: {nh} px tall, {max(pt - top, 0) + max(bottom - pb, 0):.0f} px outside "
            "the viewer"
        )
    if left < pl - 1 or right > pr + 1:
        problems.append("cropped left or right")
    return problems


def check_frame(geometry: dict | None) -> list[str]:
    """Problems of an HTML item from its iframe's document (see `_FRAME_GEOMETRY`)."""
    if geometry is None or geometry.get("empty"):
        return ["shows nothing: empty HTML page"]
    problems = []
    width, frame = geometry["scroll"]
    if width > frame + 1:
        problems.append(f"wider than its frame: {width} px in {frame} px")
    if geometry.get("broken"):
        problems.append(f"words broken across lines: {geometry['broken']}")
    return problems


def _in_frame(driver, script: str):
    """Run `script` inside the viewer's iframe (a data: URI: only the driver may enter it)."""
    frames = driver.find_elements("css selector", "iframe")
    if not frames:
        return None
    driver.switch_to.frame(frames[0])
    try:
        return driver.execute_script(script)
    finally:
        driver.switch_to.default_content()


def _wait(fn, timeout: float = 5.0, every: float = 0.05):
    """Poll `fn` until it returns something truthy (or `timeout` seconds pass); its last value."""
    end = time.monotonic() + timeout
    value = fn()
    while not value and time.monotonic() < end:
        time.sleep(every)
        value = fn()
    return value


def _open_subcategory(driver, uri: str, cat: str, sub: str, subcats: list[str]) -> None:
    """The category in the menu (back to the menu through the breadcrumb's "Results", or a
    fresh page), then the subcategory if it has several."""
    crumbs = [a for a in driver.find_elements("xpath", "//nav//a[text()='Results']")]
    if crumbs and crumbs[0].is_displayed():
        crumbs[0].click()
    else:
        driver.get(uri)
    _wait(lambda: driver.find_elements("xpath", f"//a[span[normalize-space(text())='{cat}']]"))
    _click_text(driver, cat)
    if len(subcats) > 1 or sub != "Other":
        if _wait(lambda: driver.find_elements("xpath", f"//a[span[text()='{sub}']]"), 2.0):
            _click_text(driver, sub)
    _wait(lambda: driver.find_elements("css selector", "a[iconname=eye]"))


def browse(report: Path, shots: Path | None = None, viewport: tuple[int, int] = (1600, 1000)):
    """Every category, subcategory and result of `report` as a reader meets them.

    `viewport`: the browser's (width, height) in CSS px.
    Returns (categories in menu order, visits, problems of the report as a whole)."""
    width, height = viewport
    visits: list[Visit] = []
    report_problems: list[str] = []
    uri = report.resolve().as_uri()
    if shots is not None:
        shots.mkdir(parents=True, exist_ok=True)
    with chromium(width, height) as driver:
        driver.get(uri)
        _wait(lambda: driver.execute_script("return typeof categories !== 'undefined'"))
        categories = driver.execute_script("return Object.keys(categories)")
        menu = _wait(lambda: [t for t in _menu_labels(driver) if t in categories])
        if shots is not None:
            driver.save_screenshot(str(shots / "00-landing.png"))
        if [page_of(c) for c in menu[:1]] != [FINDINGS]:
            report_problems.append(
                f"the first category is {menu[:1]}, not the findings page ({FINDINGS!r})"
            )
        results = driver.execute_script(
            "return Object.fromEntries(Object.entries(results).map(([k, v]) => [k, "
            "{caption: v.caption, name: v.name, mime: v.mime_type, labels: v.labels || {}}]))"
        )
        for cat in menu:
            subcats = driver.execute_script(
                "return Object.keys(categories[arguments[0]]).sort((a, b) => a.localeCompare(b))",
                cat,
            )
            for sub in subcats:
                paths = driver.execute_script(
                    "return categories[arguments[0]][arguments[1]]", cat, sub
                )
                _open_subcategory(driver, uri, cat, sub, subcats)
                if shots is not None:
                    driver.save_screenshot(str(shots / f"{_slug(cat, sub)}--list.png"))
                for ri, path in enumerate(paths):
                    meta = results[path]
                    kind = "img" if meta["mime"].startswith("image/") else "html"
                    visit = Visit(cat, sub, meta["name"], kind)
                    visit.problems += check_caption(meta.get("caption") or "", meta["name"])
                    row = _row_of(driver, meta["labels"])
                    if row is None:
                        visit.problems.append("not listed in its category")
                    else:
                        row.find_element("css selector", "a[iconname=eye]").click()
                        if kind == "img":
                            geometry = _wait(lambda: driver.execute_script(_IMAGE_GEOMETRY))
                            if geometry is not None:  # wait until the image has decoded
                                geometry = (
                                    _wait(
                                        lambda: (
                                            (g := driver.execute_script(_IMAGE_GEOMETRY))
                                            and g["natural"][0] > 0
                                            and g
                                        )
                                    )
                                    or geometry
                                )
                            visit.problems += check_image(geometry)
                        else:
                            geometry = _wait(
                                lambda: (
                                    (g := _in_frame(driver, _FRAME_GEOMETRY))
                                    and not g.get("empty")
                                    and g
                                )
                            )
                            visit.problems += check_frame(geometry)
                    if shots is not None:
                        visit.shot = str(
                            shots / f"{_slug(cat, sub)}--{ri:02d}-{_slug(meta['name'])}.png"
                        )
                        driver.save_screenshot(visit.shot)
                    visits.append(visit)
    return menu, visits, report_problems


def _slug(*parts: str) -> str:
    return "--".join(re.sub(r"[^A-Za-z0-9]+", "-", p).strip("-").lower() for p in parts)


def check_caption(caption_html: str, name: str) -> list[str]:
    """Problems of a result's caption: missing, only a file name, or a template left unfilled."""
    text = re.sub(r"<[^>]+>", "", caption_html).strip()
    if len(text) < 20 or text == name:
        return ["no caption"]
    if "{{" in text or "{%" in text:
        return ["caption has an unfilled template"]
    return []


def _row_of(driver, labels: dict):
    """The row of the results list that shows `labels`, or None. A label with two values is a
    toggle above the list (its value is set by clicking it); the others are the row's columns."""
    for key, value in labels.items():
        if driver.find_elements("id", f"toggle-{key}-{value}"):
            driver.find_element("css selector", f"label[for='toggle-{key}-{value}']").click()
    # the table's header and every row's cells in one script (the last column is the eye)
    heads, rows = driver.execute_script(_TABLE_TEXT)
    heads = [h.strip().lower() for h in heads]
    want = {str(k).lower(): str(v) for k, v in labels.items() if str(k).lower() in heads}
    for i, cells in enumerate(rows):
        shown = {h: c.strip() for h, c in zip(heads, cells, strict=False) if c.strip()}
        if shown and shown == want:
            return driver.find_elements("css selector", "table tbody tr")[i]
    return None


_TABLE_TEXT = """
const text = el => el.innerText;
const heads = [...document.querySelectorAll('table thead th')].slice(0, -1).map(text);
const rows = [...document.querySelectorAll('table tbody tr')].map(
    tr => [...tr.querySelectorAll('td')].slice(0, -1).map(text));
return [heads, rows];
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("report", type=Path)
    ap.add_argument("--shots", type=Path, default=None, help="save a screenshot of every view")
    ap.add_argument("--size", default="1600x1000", help="viewport, WIDTHxHEIGHT CSS px")
    args = ap.parse_args(argv)
    size = tuple(int(x) for x in args.size.split("x"))
    menu, visits, problems = browse(args.report, args.shots, size)  # type: ignore[arg-type]
    print("categories:", " | ".join(menu))
    for v in visits:
        status = "ok" if not v.problems else "; ".join(v.problems)
        print(f"{v.category} / {v.subcategory} / {v.name} [{v.kind}]: {status}")
    for p in problems:
        print("report:", p)
    bad = sum(bool(v.problems) for v in visits) + len(problems)
    print(f"browse: {len(visits)} results, {bad} with problems")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
