"""The documentation site (docs/conf.py, `make docs`): it builds with warnings as errors, a
reader finds the API reference of ``InternalResidual`` from the front page in a real browser,
and each page shows the figures ``apps.doc_figures`` draws for it."""

import re
import subprocess
import sys
from html import unescape
from pathlib import Path
from urllib.parse import urljoin

import pytest

from apps import doc_figures
from tests.headless_chromium import requires_chromium, run_chromium

ROOT = Path(__file__).resolve().parents[1]
CLASS = "systems.residuals.momentum_residuals.InternalResidual"


def _dump_dom(url: str, tmp_path: Path, name: str) -> str:
    """The page's DOM after headless Chromium loaded it (and ran its scripts), offline."""
    return run_chromium(["--dump-dom"], url, tmp_path, name, lambda dom: "</html>" in dom)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built as `make docs` builds it (the figures drawn into docs/_generated/figures
    from the committed results files, then Sphinx with warnings as errors) into a temporary
    folder; the pages are not rewritten (``--out``)."""
    tmp_path = tmp_path_factory.mktemp("docs")
    figures = subprocess.run(
        [sys.executable, "-m", "apps.doc_figures", "--out", str(doc_figures.FIGURES_DIR)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert figures.returncode == 0, f"apps.doc_figures failed:\n{figures.stderr[-3000:]}"
    html = tmp_path / "html"
    build = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q"]
        + ["-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(html)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert build.returncode == 0, f"sphinx failed (warnings are errors):\n{build.stderr[-6000:]}"
    return html


@pytest.mark.slow
def test_each_page_shows_its_figures(site):
    """Each figure of ``apps.doc_figures`` is an <img> of its page in the built site, and the
    image the page loads is the one drawn from the results files."""
    for spec in doc_figures.FIGURES:
        page = (site / spec.page).with_suffix(".html").read_text()
        sources = [unescape(s) for s in re.findall(r'<img\b[^>]*\bsrc="([^"]+)"', page)]
        mine = [s for s in sources if s.rsplit("/", 1)[-1] == f"{spec.name}.png"]
        assert len(mine) == 1, f"{spec.page}: no single <img> of {spec.name}.png (images: {sources})"
        image = (site / spec.page).parent / mine[0]
        assert image.is_file(), f"{spec.page}: {mine[0]} is not in the build"
        assert image.read_bytes() == (doc_figures.FIGURES_DIR / f"{spec.name}.png").read_bytes()
        assert f"results/{spec.sources[0]}.json" in page, (
            f"{spec.page}: the caption of {spec.name} names no results file"
        )


@requires_chromium
@pytest.mark.slow
def test_docs_build_and_the_internal_residual_page_opens_in_headless_chromium(site, tmp_path):
    """Opens the built site's front page in headless Chromium, follows the navigation's link
    to ``InternalResidual``'s page and checks that the page documents the class (its
    signature, its docstring and its methods)."""
    index = (site / "index.html").resolve().as_uri()

    front = _dump_dom(index, tmp_path, "index")
    assert "API reference" in front
    links = [unescape(h) for h in re.findall(r'href="([^"]*InternalResidual[^"]*)"', front)]
    page_links = [h for h in links if h.split("#")[0].endswith(f"{CLASS}.html")]
    assert page_links, f"no link to {CLASS}'s page on the front page (links naming it: {links})"

    page_url = urljoin(index, page_links[0].split("#")[0])
    page = _dump_dom(page_url, tmp_path, "class")
    assert f'id="{CLASS}"' in page, "the page has no entry for the class"
    text = re.sub(r"<[^>]+>", "", page)
    assert "Internal (floating-base) residual, paper eq. (11)" in text  # its docstring
    assert f'id="{CLASS}.advance"' in page, "its methods (inherited from its private base included) are not documented"
