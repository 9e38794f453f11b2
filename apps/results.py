"""Results files: the figures the documentation quotes, as the apps measured them (issue 31).

An app that measures a quoted figure writes ``results/<name>.json`` (committed) with
``write_results``: the measured data, the command that produced it, when, and on which Python
and Drake. The tables of README.md, BENCHMARKS.md and docs/*.md between ``<!-- results: NAME -->``
and ``<!-- /results: NAME -->`` are generated from those files by ``python -m apps.doc_tables``
(``make docs``), and ``tests/test_doc_tables.py`` fails when a table and its file disagree: no
quoted figure is typed by hand.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import re
import shlex
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from apps.runner import json_text

#: The committed results files.
RESULTS_DIR = Path(__file__).resolve().parent.parent / "results"
#: An environment variable that sends the results files elsewhere (a trial run, a test).
RESULTS_DIR_VARIABLE = "HCO_RESULTS_DIR"


def results_path(name: str, folder: Path | None = None) -> Path:
    """``<folder>/<name>.json``; default folder: ``$HCO_RESULTS_DIR`` when set, else
    ``RESULTS_DIR``."""
    if not name or "/" in name or name.startswith("."):
        raise ValueError(f"a results name is a plain file stem, got {name!r}")
    if folder is None:
        folder = Path(os.environ.get(RESULTS_DIR_VARIABLE) or RESULTS_DIR)
    return Path(folder) / f"{name}.json"


def app_command(module: str, argv: list[str] | None) -> str:
    """The command line that ran the app ``module`` with ``argv`` (None: this process's)."""
    return shlex.join(["python", "-m", module, *(sys.argv[1:] if argv is None else argv)])


def write_results(name: str, data: dict, *, command: str, folder: Path | None = None) -> Path:
    """Writes ``data`` (JSON-able; NumPy values are converted) to ``results/<name>.json`` with
    the ``command`` that measured it (``app_command``), the date, Python's and Drake's
    versions."""
    from models.drake_compat import drake_version

    payload = {
        "name": name,
        "command": command,
        "written": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "python": platform.python_version(),
        "drake": ".".join(map(str, drake_version() or ())) or "unknown",
        "data": data,
    }
    path = results_path(name, folder)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(".json.tmp")
    temporary.write_text(json_text(payload) + "\n")
    temporary.replace(path)
    return path


def load_results(name: str, folder: Path | None = None) -> dict[str, Any]:
    """The results file ``name`` (all of it: ``data`` and its provenance).

    Raises:
        ValueError: a missing or unreadable file, naming it and the command that writes it.
    """
    path = results_path(name, folder)
    try:
        payload = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(f"results file '{path}' cannot be read ({error}): run the app that writes it") from error
    if not isinstance(payload, dict) or "data" not in payload or "command" not in payload:
        raise ValueError(f"results file '{path}' has no 'data' and 'command': not written by write_results")
    return payload


def drake_release(drake) -> str:
    """Drake's release as ``write_results`` writes it ("1.58.0"; a list in older files)."""
    return ".".join(map(str, drake)) if isinstance(drake, list) else str(drake)


def provenance(prefix: str, name: str, payload: dict) -> str:
    """``prefix``, then the command that wrote the results file ``name`` (its ``payload``, as
    ``load_results`` reads it), when, on which Python and Drake, and the file: the line under
    each generated table and in each generated figure's caption."""
    return (
        f"{prefix} `{payload['command']}` on {payload['written']} (Python {payload['python']}, "
        f"Drake {drake_release(payload['drake'])}; `results/{name}.json`)"
    )


def generated_block_pattern(tag: str) -> re.Pattern:
    """The generated blocks ``<!-- TAG: NAME -->`` ... ``<!-- /TAG: NAME -->`` of a document
    (groups: opening line, ``name``, ``body``, closing line)."""
    return re.compile(rf"(<!-- {tag}: (?P<name>[\w.-]+) -->\n)(?P<body>.*?)(<!-- /{tag}: (?P=name) -->)", re.S)


def regenerated_blocks(pattern: re.Pattern, text: str, render: Callable[[str], str]) -> tuple[str, list[str]]:
    """``text`` with the body of every block of ``pattern`` replaced by ``render(name)``, and
    the names of the blocks whose body changed."""
    changed = []

    def replace(match: re.Match) -> str:
        body = render(match["name"])
        if body != match["body"]:
            changed.append(match["name"])
        return match.group(1) + body + match.group(4)

    return pattern.sub(replace, text), changed


def stale_documents(
    documents: Sequence[Path], updated: Callable[[str], tuple[str, list[str]]], root: Path
) -> tuple[list[str], dict[Path, str]]:
    """Each document's stale blocks: (``<path relative to root>: <name>`` of every block that
    ``updated(text)`` changes, {path: its regenerated text} of the documents that change)."""
    stale, rewritten = [], {}
    for path in documents:
        text, changed = updated(path.read_text())
        stale += [f"{path.relative_to(root)}: {name}" for name in changed]
        if changed:
            rewritten[path] = text
    return stale, rewritten


__all__ = [
    "RESULTS_DIR",
    "RESULTS_DIR_VARIABLE",
    "app_command",
    "drake_release",
    "generated_block_pattern",
    "load_results",
    "provenance",
    "regenerated_blocks",
    "results_path",
    "stale_documents",
    "write_results",
]
