"""The documentation site reads offline: its equations are typeset by a MathJax copied into the site, not a CDN's.

A one-page site is built with the documentation's own configuration (``docs/conf.py``: its extensions but the
gallery's, which runs every example; its theme and static files) and its page is checked: every script
and style sheet is a path inside the site, MathJax among them. Where headless Chromium and Selenium are installed
(see ``tests/report/test_browser.py``), the page is also opened with every host name unresolvable, and the
equations must be typeset.
"""

from __future__ import annotations

import os
import re
import runpy
import shutil
import subprocess
import sys
from pathlib import Path
from urllib.parse import urlsplit

import pytest

pytest.importorskip("sphinx", reason="building the documentation needs the 'docs' extra (sphinx)")

DOCS = Path(__file__).resolve().parents[2] / "docs"

PAGE = r"""Equations
=========

The beta-divergence of :math:`V` from :math:`W H`:

.. math::

   D_\beta(V \| W H) = \sum_{i, j} d_\beta\left(V_{ij}, (W H)_{ij}\right)
"""


@pytest.fixture(scope="module")
def conf() -> dict:
    """The names ``docs/conf.py`` defines."""
    saved = dict(os.environ)
    try:
        return runpy.run_path(str(DOCS / "conf.py"))
    finally:  # conf.py sets the build's environment (no data root, a headless matplotlib)
        os.environ.clear()
        os.environ.update(saved)


@pytest.fixture(scope="module")
def page(conf, tmp_path_factory) -> Path:
    """The built page (``index.html``) of a one-page site with the documentation's configuration."""
    src = tmp_path_factory.mktemp("docs-src")
    (src / "index.rst").write_text(PAGE)
    out = src.parent / "docs-html"
    extensions = [e for e in conf["extensions"] if not e.startswith("sphinx_gallery")]  # it runs every example
    cmd = [sys.executable, "-m", "sphinx", "-W", "-q", "-b", "html", "-c", str(DOCS),
           "-D", "extensions=" + ",".join(extensions), str(src), str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return out / "index.html"


def _assets(html: str) -> list[str]:
    """The scripts (``src``) and linked files (``href`` of ``<link>``) the page loads."""
    return ([m.group(1) for m in re.finditer(r"<script\b[^>]*\bsrc=\"([^\"]+)\"", html)]
            + [m.group(1) for m in re.finditer(r"<link\b[^>]*\bhref=\"([^\"]+)\"", html)])


def test_the_page_loads_nothing_from_another_host(page):
    assets = _assets(page.read_text())
    assert assets
    remote = [a for a in assets if urlsplit(a).scheme or a.startswith("//")]
    assert remote == []
    for asset in assets:  # each one is in the site
        assert (page.parent / urlsplit(asset).path).is_file(), asset


def test_mathjax_is_in_the_site_and_the_equations_are_in_the_page(page):
    html = page.read_text()
    mathjax = [a for a in _assets(html) if "mathjax" in a.lower()]
    assert len(mathjax) == 1 and mathjax[0].startswith("_static/")
    assert (page.parent / mathjax[0]).is_file()
    assert r"D_\beta(V \| W H)" in html and r"\(W H\)" in html  # display and inline, for MathJax to typeset


def test_the_gallery_writes_no_page_that_loads_scripts_from_a_cdn(conf):
    # sphinx-gallery's pages of the examples' run times (sg_execution_times) load jQuery and DataTables from CDNs
    assert conf["sphinx_gallery_conf"]["write_computation_times"] is False


def _chromium() -> tuple[str, str] | None:
    browser = os.environ.get("MMCONCEPTS_CHROMIUM") or next(
        (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
    driver = os.environ.get("MMCONCEPTS_CHROMEDRIVER") or shutil.which("chromedriver")
    return (browser, driver) if browser and driver else None


def test_the_equations_are_typeset_without_a_network(page):
    pytest.importorskip("selenium", reason="the browser check needs the 'test' extra (selenium)")
    found = _chromium()
    if found is None:
        pytest.skip("the browser check needs Chromium and chromedriver (Debian: chromium, chromium-driver)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.support.ui import WebDriverWait

    os.environ.setdefault("SE_OFFLINE", "true")  # Selenium Manager looks nothing up
    options = webdriver.ChromeOptions()
    options.binary_location = found[0]
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--allow-file-access-from-files", "--disable-background-networking",
                "--host-resolver-rules=MAP * ~NOTFOUND"):  # no host name resolves: a CDN cannot be reached
        options.add_argument(arg)
    try:
        driver = webdriver.Chrome(service=Service(executable_path=found[1]), options=options)
    except Exception as exc:  # noqa: BLE001 - a browser that cannot start here is a skip, with the reason
        pytest.skip(f"headless Chromium does not start here ({type(exc).__name__}: {str(exc).splitlines()[0]})")
    try:
        driver.get(page.as_uri())
        count = "return document.querySelectorAll('mjx-container').length"
        WebDriverWait(driver, 30).until(lambda d: d.execute_script(count) == 3, "MathJax typeset no equation")
        # typeset for real: glyphs with a width, not the TeX source left as text
        widths = driver.execute_script(
            "return Array.from(document.querySelectorAll('mjx-container')).map(e => e.getBoundingClientRect().width)")
        assert all(w > 0 for w in widths)
        assert r"\sum" not in driver.find_element("tag name", "body").text
    finally:
        driver.quit()
