"""Module layout rules of ``service/`` (docs/architecture.md): settings is a leaf module and
every import is absolute."""

from __future__ import annotations

import ast
from pathlib import Path

SERVICE = Path(__file__).resolve().parents[2] / "service"


def imported_modules(path: Path) -> list[str]:
    """Top-level module names imported anywhere in ``path`` (``None`` for relative ones)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            out.append(node.module if node.level == 0 else None)
    return out


def test_settings_imports_only_pydantic_and_the_standard_library():
    allowed = {"pydantic", "pydantic_settings", "__future__", "contextvars", "dataclasses",
               "datetime", "pathlib", "re", "typing"}
    mods = imported_modules(SERVICE / "settings.py")
    assert {m.split(".")[0] for m in mods} <= allowed, mods


def test_service_uses_absolute_imports_only():
    for path in SERVICE.rglob("*.py"):
        assert None not in imported_modules(path), f"relative import in {path}"
