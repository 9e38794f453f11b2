"""Conventions checked on the source with ``ast``: the project's own systems' ports are reached
by name (``GetInputPort("state")``, ``GetOutputPort("residual")``), so no class under
``systems/`` defines a typed accessor method ``get_<name>_port`` (Drake's systems keep theirs:
``plant.get_state_output_port()``)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PORT_ACCESSOR = re.compile(r"get_\w+_port")


def port_accessors(source: str, where: str = "<source>") -> list[str]:
    """``where:line: Class.method`` of every method named ``get_*_port`` of a class in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and PORT_ACCESSOR.fullmatch(item.name):
                    found.append(f"{where}:{item.lineno}: {node.name}.{item.name}")
    return found


def test_the_check_finds_a_port_accessor():
    source = (
        "class A:\n"
        "    def get_state_input_port(self):\n        return self._state\n"
        "    def state(self):\n        pass\n"
        "class B:\n"
        "    class C:\n        def get_residual_output_port(self):\n            pass\n"
    )
    assert port_accessors(source) == ["<source>:2: A.get_state_input_port", "<source>:8: C.get_residual_output_port"]


def test_no_system_has_a_typed_port_accessor():
    files = sorted(p for p in (ROOT / "systems").rglob("*.py") if "__pycache__" not in p.parts)
    assert len(files) > 20
    found = [hit for path in files for hit in port_accessors(path.read_text(), str(path.relative_to(ROOT)))]
    assert found == [], "ports are reached by name (GetInputPort/GetOutputPort), not by accessors:\n" + "\n".join(found)
