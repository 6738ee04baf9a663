"""The package's layout: layers that import only the layers below them, no import cycles
(the import-linter contracts in pyproject.toml), and no private name imported from another
subpackage (a subpackage's internals stay its own)."""

import ast
import pathlib
import subprocess
import sys

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "absorber_jax"


def test_import_linter_contracts_are_kept():
    exe = pathlib.Path(sys.executable).parent / "lint-imports"
    out = subprocess.run([str(exe)], cwd=PACKAGE.parent, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert "Contracts: 2 kept, 0 broken." in out.stdout


def _cross_subpackage_private_imports():
    found = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        here = list(rel.parts[:-1])
        own = here[0] if here else ""
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.ImportFrom) and node.level >= 1 and node.module):
                continue
            base = here[:len(here) - (node.level - 1)]
            target = (base + node.module.split("."))[0]
            if target != own:
                found += [f"{rel}: {node.module}.{a.name}" for a in node.names
                          if a.name.startswith("_")]
    return found


def test_no_private_name_crosses_a_subpackage():
    assert _cross_subpackage_private_imports() == []


def test_the_check_sees_a_private_import(tmp_path, monkeypatch):
    """The scan above finds a planted violation (so an empty result means something)."""
    global PACKAGE
    pkg = tmp_path / "absorber_jax"
    (pkg / "_a").mkdir(parents=True)
    (pkg / "_a" / "x.py").write_text("from .._b.y import _hidden\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", pkg)
    assert _cross_subpackage_private_imports() == ["_a/x.py: _b.y._hidden"]
