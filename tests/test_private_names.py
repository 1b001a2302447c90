"""No module imports another module's private name: a module that needs another's
``_helper`` is asking for a public stage (the import-linter contracts in pyproject.toml
check the cycles and the private modules)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("app", "drivers", "processing", "hardware_mocks")


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def private_imports(source: str, module: str) -> list[str]:
    """``from other import _name`` (and ``import other._name`` stays a module import, which
    the contract covers) in ``source`` of ``module``: ``"module: other._name"`` each."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom) or node.module is None or node.level:
            continue
        if node.module == module:
            continue
        for alias in node.names:
            as_module = ROOT.joinpath(*node.module.split("."), alias.name)
            if as_module.with_suffix(".py").is_file() or as_module.is_dir():
                continue  # a private module of its package: the import-linter contract's
            if alias.name.startswith("_") and not alias.name.startswith("__"):
                found.append(f"{module}: {node.module}.{alias.name}")
    return found


def test_the_check_finds_a_private_import() -> None:
    src = "from processing.identify import _iterate, fit\nfrom processing.x import y\n"
    assert private_imports(src, "processing.bootstrap") == [
        "processing.bootstrap: processing.identify._iterate"]
    assert private_imports("from processing.x import _y\n", "processing.x") == []


def test_no_module_imports_another_modules_private_name() -> None:
    found = [hit for pkg in PACKAGES for path in sorted((ROOT / pkg).rglob("*.py"))
             for hit in private_imports(path.read_text(encoding="utf-8"), _module(path))]
    assert found == [], "private names imported across modules:\n" + "\n".join(found)
