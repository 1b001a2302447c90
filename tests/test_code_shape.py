"""The shape of the code: short functions, a small spectral module, no silenced type checks.

Each check names what breaks it, so a failure says where to look.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the packages whose functions and methods are held to :data:`MAX_FUNCTION_LINES`
PACKAGES = ("app", "processing", "drivers")
#: longest function or method, lines from ``def`` to its last line, docstring included
MAX_FUNCTION_LINES = 80
#: the Welch spectra: the public module and its compiled kernel, lines together
SPECTRAL_FILES = ("processing/spectral.py", "processing/_welch_kernel.py")
MAX_SPECTRAL_LINES = 900
#: folders where every type is checked: no ``type: ignore`` comment
NO_IGNORE_DIRS = ("app/acquire", "drivers")
_IGNORE = re.compile(r"#\s*type:\s*ignore")


def _python_files(*folders: str) -> list[Path]:
    return sorted(p for folder in folders for p in (ROOT / folder).rglob("*.py"))


def _functions(tree: ast.AST) -> list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
    """Every function and method of a module, with its qualified name (``Class.method``)."""
    found: list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                found.append((prefix + child.name, child))
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return found


def long_functions(paths: list[Path], limit: int, root: Path = ROOT) -> list[str]:
    """``"<lines> <file>:<line> <name>"`` of each function or method over ``limit`` lines,
    the file relative to ``root``."""
    out = []
    for path in paths:
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for name, node in _functions(tree):
            assert node.end_lineno is not None
            n = node.end_lineno - node.lineno + 1
            if n > limit:
                out.append(f"{n} {path.relative_to(root)}:{node.lineno} {name}")
    return out


def test_no_function_is_longer_than_the_limit() -> None:
    paths = _python_files(*PACKAGES)
    assert paths, f"no Python file under {PACKAGES} in {ROOT}"
    long = long_functions(paths, MAX_FUNCTION_LINES)
    assert not long, (f"{len(long)} function(s) over {MAX_FUNCTION_LINES} lines: split them "
                      "into helpers that do one thing each:\n" + "\n".join(long))


def test_the_spectral_module_and_its_kernel_stay_small() -> None:
    counts = {name: len((ROOT / name).read_text(encoding="utf-8").splitlines())
              for name in SPECTRAL_FILES}
    total = sum(counts.values())
    assert total <= MAX_SPECTRAL_LINES, (
        f"{' + '.join(f'{n} ({c})' for n, c in counts.items())} = {total} lines, more than "
        f"{MAX_SPECTRAL_LINES}: remove repetition before adding")


def test_no_type_ignore_in_acquisition_and_drivers() -> None:
    paths = _python_files(*NO_IGNORE_DIRS)
    assert paths, f"no Python file under {NO_IGNORE_DIRS} in {ROOT}"
    found = [f"{path.relative_to(ROOT)}:{k}: {line.strip()}"
             for path in paths
             for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
             if _IGNORE.search(line)]
    assert not found, ("type: ignore silences mypy here; type the code instead (a typed "
                       "kwargs, typing.cast, an explicit conversion):\n" + "\n".join(found))


def test_the_length_check_counts_docstrings_and_names_methods(tmp_path: Path) -> None:
    # the checker itself, limit 2: a 3-line method (docstring included), a 4-line function
    # holding a 2-line one
    probe = tmp_path / "probe.py"
    probe.write_text('class A:\n    def f(self):\n        """Doc."""\n        return 1\n\n\n'
                     "def g():\n    def h():\n        pass\n    return h\n", encoding="utf-8")
    assert long_functions([probe], 2, root=tmp_path) == ["3 probe.py:2 A.f", "4 probe.py:7 g"]
