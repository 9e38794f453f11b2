"""The documentation site (docs/conf.py, `make docs`): it builds with warnings as errors, and a
reader finds the API reference of ``InternalResidual`` from the front page in a real browser."""

import re
import subprocess
import sys
from html import unescape
from pathlib import Path
from urllib.parse import urljoin

import pytest

from tests.headless_chromium import requires_chromium, run_chromium

ROOT = Path(__file__).resolve().parents[1]
CLASS = "systems.residuals.momentum_residuals.InternalResidual"


def _dump_dom(url: str, tmp_path: Path, name: str) -> str:
    """The page's DOM after headless Chromium loaded it (and ran its scripts), offline."""
    return run_chromium(["--dump-dom"], url, tmp_path, name, lambda dom: "</html>" in dom)


@requires_chromium
@pytest.mark.slow
def test_docs_build_and_the_internal_residual_page_opens_in_headless_chromium(tmp_path):
    """Builds the site as `make docs` does (Sphinx, warnings as errors) into a temporary folder,
    opens its front page in headless Chromium, follows the navigation's link to
    ``InternalResidual``'s page and checks that the page documents the class (its signature,
    its docstring and its methods)."""
    html = tmp_path / "html"
    build = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q"]
        + ["-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(html)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert build.returncode == 0, f"sphinx failed (warnings are errors):\n{build.stderr[-6000:]}"
    index = (html / "index.html").resolve().as_uri()

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
