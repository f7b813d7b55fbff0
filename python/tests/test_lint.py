"""The package's Python, its tests and benchmarks are lint-clean (ruff with python/pyproject.toml's rules), and the
package's modules import one another without a circle."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PYTHON = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    pytest.importorskip("ruff")
    out = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "."], capture_output=True, text=True,
                         cwd=PYTHON)
    assert out.returncode == 0, out.stdout + out.stderr


def imports_of(path):
    """The package's modules that `path` imports (relative imports, also those inside functions)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            found.update([node.module.split(".")[0]] if node.module else [a.name for a in node.names])
    return found - {"_arld"}


def test_the_modules_import_without_a_circle():
    graph = {p.stem: imports_of(p) for p in (PYTHON / "arld").glob("*.py")}
    assert graph["agent"] >= {"callbacks", "experts", "envs"}  # the check sees the imports

    def reach(start):
        seen, todo = set(), list(graph[start])
        while todo:
            module = todo.pop()
            if module not in seen:
                seen.add(module)
                todo.extend(graph.get(module, ()))
        return seen

    circles = sorted(m for m in graph if m in reach(m))
    assert circles == [], {m: sorted(graph[m]) for m in circles}
