"""``report.html`` checked in a real browser: headless Chromium driven by Selenium.

The report is built from a small results folder (the toy experiments' records, a real
record of ``tests/data/records`` whose figure files are absent, and a damaged record), then
opened in headless Chromium. Asserted: no console errors, every ``<img>`` loaded
(``naturalWidth > 0``), every ``<audio>`` loaded (its metadata read, a finite duration) and
playing (muted), every in-page link (``#anchor``) names an element, the contents stay
in view after scrolling to the bottom, and following an anchor into a closed section opens
it. A run with a concept explorer (the toy's) has its clips' durations checked against the
clips written, its thumbnails and animated motions loaded. Screenshots go to
``tests/.artifacts/report.png`` (and ``report-bottom.png``, ``explorer.png``) for a developer
to look at. Other tests break a report (an image path, an anchor, a script error, an audio,
thumbnail or motion path) and check that the same inspection catches each break.

Needs Debian's ``chromium`` and ``chromium-driver`` packages (``make test`` installs them
where it can) and the ``selenium`` package (the ``test`` extra); the tests skip, naming
what is missing, otherwise. Nothing is downloaded at run time: the driver is given by
path, so Selenium Manager is never asked for one.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from mmconcepts.experiments import register, reproduce
from mmconcepts.report import write_report

TESTS = Path(__file__).resolve().parents[1]
ARTIFACTS = TESTS / ".artifacts"


def _find(*names: str) -> str | None:
    for name in names:
        path = shutil.which(name)
        if path:
            return path
    return None


CHROMIUM = os.environ.get("MMCONCEPTS_CHROMIUM") or _find("chromium", "chromium-browser", "google-chrome")
CHROMEDRIVER = os.environ.get("MMCONCEPTS_CHROMEDRIVER") or _find("chromedriver")


def _missing() -> str | None:
    missing = []
    if CHROMIUM is None:
        missing.append("a Chromium browser (Debian package 'chromium')")
    if CHROMEDRIVER is None:
        missing.append("chromedriver (Debian package 'chromium-driver')")
    try:
        import selenium  # noqa: F401
    except ImportError:
        missing.append("the Python package 'selenium' (pip install -e '.[test]')")
    if missing:
        return ("the browser test of the report needs " + " and ".join(missing)
                + "; `make test` installs the Debian packages when run as root or with sudo")
    return None


pytestmark = pytest.mark.skipif(_missing() is not None, reason=_missing() or "")


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium (one per module), its console log kept."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    os.environ.setdefault("SE_OFFLINE", "true")  # never let Selenium Manager look anything up
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000", "--hide-scrollbars", "--allow-file-access-from-files",
                "--disable-extensions", "--no-first-run", "--disable-background-networking",
                "--autoplay-policy=no-user-gesture-required"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    except Exception as exc:  # noqa: BLE001 - a browser that cannot start here is a skip, with the reason
        pytest.skip(f"headless Chromium does not start here ({type(exc).__name__}: {str(exc).splitlines()[0]})")
    driver.set_page_load_timeout(60)
    driver.set_script_timeout(60)
    yield driver
    driver.quit()


@pytest.fixture
def report_dir(toy, tmp_path):
    """A results folder: toy runs (ok with a figure, failed, skipped), a real record, a damaged one."""
    register(toy.FAIL)
    register(toy.SKIP)
    out = tmp_path / "results"
    reproduce(output=out, progress=False)
    shutil.copy(TESTS / "data" / "records" / "ch3-combinations.synthetic.json", out)  # its figure file is absent
    shutil.copy(TESTS / "data" / "records" / "ch2-nmf-recovery.json", out)
    good = json.loads((out / "toy-mean.json").read_text())
    (out / "cut.json").write_text(json.dumps(good)[:300])
    write_report(out)
    return out


_INSPECT = """
const done = arguments[arguments.length - 1];
const imgs = Array.from(document.images);
imgs.forEach(img => { img.loading = "eager"; });
Promise.all(imgs.map(img => img.complete ? null : new Promise(r => {
    img.addEventListener("load", r); img.addEventListener("error", r); }))).then(() => {
  const links = Array.from(document.querySelectorAll('a[href^="#"]')).map(a => a.getAttribute("href"));
  const ids = Array.from(document.querySelectorAll("[id]")).map(e => e.id);
  done({
    images: imgs.map(img => [img.getAttribute("src"), img.complete, img.naturalWidth]),
    dangling: links.filter(h => !document.getElementById(decodeURIComponent(h.slice(1)))),
    n_links: links.length,
    duplicate_ids: ids.filter((id, i) => ids.indexOf(id) !== i),
    sections: document.querySelectorAll("details.experiment").length,
    open_sections: document.querySelectorAll("details.experiment[open]").length,
  });
});
"""

#: Every <audio> of the page: wait for its metadata (or its error), then play it muted and see it go.
_AUDIO = """
const done = arguments[arguments.length - 1];
const clips = Array.from(document.querySelectorAll("audio"));
const ready = a => a.readyState >= 1 || a.error ? Promise.resolve() : new Promise(r => {
    a.addEventListener("loadedmetadata", r); a.addEventListener("error", r); setTimeout(r, 10000); });
Promise.all(clips.map(a => { a.preload = "auto"; a.load(); return ready(a); })).then(async () => {
  const out = [];
  for (const a of clips) {
    let played = null;
    if (!a.error && a.readyState >= 1) {
      a.muted = true;
      try { await a.play(); await new Promise(r => setTimeout(r, 250)); played = !a.paused || a.ended || a.currentTime > 0; }
      catch (e) { played = String(e); }
      a.pause();
    }
    out.push({src: a.getAttribute("src"), ready: a.readyState, duration: a.duration,
              error: a.error ? a.error.code : null, played: played});
  }
  done(out);
});
"""

_TOC_IN_VIEW = """
const toc = document.getElementById("toc");
if (!toc) return {found: false};
const r = toc.getBoundingClientRect();
const x = r.left + Math.min(20, r.width / 2), y = Math.max(r.top, 0) + 20;
const hit = document.elementFromPoint(x, y);
return {found: true, top: r.top, bottom: r.bottom, height: r.height, width: r.width, inner: window.innerHeight,
        scrolled: window.scrollY, page: document.documentElement.scrollHeight, hit_in_toc: !!hit && toc.contains(hit)};
"""


def _console_errors(driver) -> list[str]:
    return [entry["message"] for entry in driver.get_log("browser") if entry.get("level") == "SEVERE"]


def inspect(driver, html_path: Path, *, screenshot: str | None = None) -> dict:
    """Open ``html_path`` and return what the tests assert on."""
    driver.get_log("browser")  # drop what earlier pages logged
    driver.get(html_path.resolve().as_uri())
    found = driver.execute_async_script(_INSPECT)
    found["audio"] = driver.execute_async_script(_AUDIO)
    if screenshot:
        ARTIFACTS.mkdir(exist_ok=True)
        driver.save_screenshot(str(ARTIFACTS / f"{screenshot}.png"))
    driver.execute_script("window.scrollTo(0, document.documentElement.scrollHeight);")
    found["toc"] = driver.execute_script(_TOC_IN_VIEW)
    if screenshot:
        driver.save_screenshot(str(ARTIFACTS / f"{screenshot}-bottom.png"))
    found["console_errors"] = _console_errors(driver)
    return found


def _problems(found: dict) -> list[str]:
    """Everything wrong with an inspected page, in words."""
    problems = [f"console error: {m}" for m in found["console_errors"]]
    problems += [f"image not loaded: {src}" for src, complete, width in found["images"] if not (complete and width > 0)]
    problems += [f"audio not loaded: {a['src']} ({a})" for a in found["audio"]
                 if a["error"] is not None or a["ready"] < 1 or not (a["duration"] or 0) > 0]
    problems += [f"audio does not play: {a['src']} ({a['played']})" for a in found["audio"]
                 if a["error"] is None and a["ready"] >= 1 and a["played"] is not True]
    problems += [f"link to a missing anchor: {h}" for h in found["dangling"]]
    problems += [f"duplicate id: {i}" for i in found["duplicate_ids"]]
    toc = found["toc"]
    if not toc.get("found"):
        problems.append("no table of contents (#toc)")
    elif not (toc["height"] > 0 and toc["width"] > 0 and -1 <= toc["top"] < toc["inner"] and toc["hit_in_toc"]):
        problems.append(f"the table of contents is out of view after scrolling to the bottom: {toc}")
    return problems


def test_report_renders_in_headless_chromium(browser, report_dir):
    found = inspect(browser, report_dir / "report.html", screenshot="report")
    assert _problems(found) == []
    assert len(found["images"]) == 1  # toy-mean's histogram; the absent figures are named, not <img>
    assert found["sections"] == 6 and found["open_sections"] == 6  # one per experiment, open by default
    assert found["n_links"] > 30
    assert found["toc"]["scrolled"] > 0 and found["toc"]["page"] > found["toc"]["inner"]  # it did scroll
    assert (ARTIFACTS / "report.png").stat().st_size > 10_000


def test_following_an_anchor_opens_a_closed_section(browser, report_dir):
    browser.get((report_dir / "report.html").resolve().as_uri())
    browser.execute_script('document.querySelectorAll("details.experiment").forEach(d => d.open = false);')
    claim = browser.execute_script('return document.querySelector("tr[id*=-claim-]").id;')
    browser.execute_script("location.hash = arguments[0];", claim)
    opened = browser.execute_script(
        "return document.getElementById(arguments[0]).closest('details.experiment').open;", claim)
    assert opened
    assert _console_errors(browser) == []


@pytest.fixture
def explorer_dir(toy, tmp_path):
    """A results folder with a run that has a concept explorer (the toy's: tones, ramps, a stick figure, curves)."""
    register(toy.CONCEPTS)
    out = tmp_path / "results"
    reproduce(output=out, progress=False, ids=["toy-concepts"])
    write_report(out)
    return out


def test_the_concept_explorer_plays_and_shows_in_headless_chromium(browser, explorer_dir, toy):
    record = json.loads((explorer_dir / "toy-concepts.json").read_text())
    clips = [c for card in record["explorer"]["cards"] for c in card["clips"]]
    pictures = [m["path"] for card in record["explorer"]["cards"] for kind in ("images", "motions") for m in card[kind]]
    found = inspect(browser, explorer_dir / "report.html", screenshot="explorer")
    assert _problems(found) == []
    # every clip: its metadata loaded, its duration the clip's, and it plays
    assert [a["src"] for a in found["audio"]] == [c["path"] for c in clips] and len(clips) == 4
    for a, clip in zip(found["audio"], clips):
        assert a["ready"] >= 1 and a["error"] is None and a["played"] is True
        assert a["duration"] == pytest.approx(clip["seconds"], abs=0.05)
    assert sorted(c["seconds"] for c in clips) == sorted([*toy.CLIP_SECONDS, toy.CLIP_SECONDS[0]])
    # every thumbnail and both motions (animated SVG) loaded
    loaded = {src: width for src, complete, width in found["images"] if complete}
    assert sorted(loaded) == sorted(pictures) and all(width > 0 for width in loaded.values())


@pytest.mark.parametrize("damage", ["audio path", "thumbnail path", "motion path"])
def test_the_browser_check_catches_a_broken_explorer(browser, explorer_dir, damage):
    path = explorer_dir / "report.html"
    text = path.read_text()
    old = {"audio path": "card-1-clip-2.wav", "thumbnail path": "card-2-image-1.png",
           "motion path": "card-1-motion-1.svg"}[damage]
    broken = text.replace(f'src="toy-concepts/explorer/{old}"', 'src="toy-concepts/explorer/nothing-here.x"')
    assert broken != text
    path.write_text(broken)
    problems = _problems(inspect(browser, path))
    expected = "audio not loaded" if damage == "audio path" else "image not loaded"
    assert any(expected in p and "nothing-here" in p for p in problems), problems


@pytest.mark.parametrize("damage", ["image path", "anchor", "script error", "toc not sticky"])
def test_the_browser_check_catches_a_broken_report(browser, report_dir, damage):
    """The inspection must fail on a broken report: each damage is caught."""
    path = report_dir / "report.html"
    text = path.read_text()
    if damage == "image path":
        broken = text.replace('src="toy-mean/hist.png"', 'src="toy-mean/nothing-here.png"')
    elif damage == "anchor":
        broken = text.replace('id="exp-toy-mean"', 'id="exp-renamed"')
    elif damage == "script error":
        broken = text.replace("</body>", "<script>undefinedFunction();</script></body>")
    else:
        broken = text.replace("</style>", ".toc { position: static; }</style>")
    assert broken != text
    path.write_text(broken)
    problems = _problems(inspect(browser, path))
    expected = {"image path": "image not loaded", "anchor": "missing anchor", "script error": "console error",
                "toc not sticky": "out of view"}[damage]
    assert any(expected in p for p in problems), problems
