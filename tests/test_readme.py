"""README.md is a front page (issue 34): short, its example runs, its links to docs/ resolve."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"

_PYTHON_BLOCK = re.compile(r"^```python\n(?P<code>.*?)^```$", re.S | re.M)


def test_readme_is_at_most_200_lines():
    lines = README.read_text().splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines: move the detail to a docs/ page"


def test_the_readme_example_runs(capsys):
    blocks = _PYTHON_BLOCK.findall(README.read_text())
    assert len(blocks) == 1, f"README.md should have exactly one ```python block, found {len(blocks)}"
    namespace = {"__name__": "readme_example"}
    exec(compile(blocks[0], "README.md (python block)", "exec"), namespace)
    residual = namespace["residual"]
    context = namespace["context"]
    plant = namespace["plant"]
    value = residual.GetOutputPort("residual").Eval(context)
    assert value.shape == (plant.num_velocities() - 6,)
    assert capsys.readouterr().out.strip(), "the example prints the residual"


def test_every_docs_link_in_the_readme_exists():
    text = README.read_text()
    targets = re.findall(r"\]\((docs/[^)#\s]+)(?:#[^)]*)?\)", text)
    assert targets, "README.md links no docs/ page"
    missing = sorted({t for t in targets if not (ROOT / t).is_file()})
    assert not missing, f"README.md links missing pages: {missing}"


def test_every_docs_page_is_linked_from_the_readme():
    text = README.read_text()
    pages = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))
    unlinked = [page for page in pages if f"({page})" not in text]
    assert not unlinked, f"docs pages the README's Documentation list does not link: {unlinked}"
