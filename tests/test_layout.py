"""The package's layout: layers that import only the layers below them, no import cycles
(the import-linter contracts in pyproject.toml), no private name imported from another
subpackage (a subpackage's internals stay its own), and equinox's abstract/final pattern (no
concrete member overridden)."""

import ast
import importlib
import inspect
import pathlib
import pkgutil
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


def _concrete_overrides(modules, package="absorber_jax"):
    """``Class.member`` for each method or property of a class in ``modules`` that overrides
    a concrete (non-abstract) one of a base class of the package: equinox's abstract/final
    pattern has every concrete member final."""
    found, seen = [], set()
    for mod in modules:
        for cls in vars(mod).values():
            if (not inspect.isclass(cls) or cls in seen
                    or not cls.__module__.startswith(package)):
                continue
            seen.add(cls)
            for attr, val in vars(cls).items():
                if attr.startswith("__") or not (inspect.isfunction(val)
                                                 or isinstance(val, property)):
                    continue
                for base in cls.__mro__[1:]:
                    if attr not in vars(base):
                        continue
                    if base.__module__.startswith(package):
                        got = vars(base)[attr]
                        got = got.fget if isinstance(got, property) else got
                        if not getattr(got, "__isabstractmethod__", False):
                            found.append(f"{cls.__name__}.{attr} ({base.__name__})")
                    break
    return sorted(found)


def _package_modules():
    import absorber_jax
    return [importlib.import_module(m.name)
            for m in pkgutil.walk_packages(absorber_jax.__path__, "absorber_jax.")
            if not m.name.endswith("__main__")]


def test_no_concrete_member_is_overridden():
    assert _concrete_overrides(_package_modules()) == []


def test_the_check_sees_an_overridden_concrete_member(tmp_path, monkeypatch):
    """The scan above finds a planted override (so an empty result means something)."""
    (tmp_path / "absorber_jax_planted.py").write_text(
        "import abc\n"
        "class Base:\n"
        "    def hook(self):\n        return 0\n"
        "    @abc.abstractmethod\n    def solve(self): ...\n"
        "class Final(Base):\n"
        "    def hook(self):\n        return 1\n"
        "    def solve(self):\n        return 2\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    planted = importlib.import_module("absorber_jax_planted")
    assert _concrete_overrides([planted], package="absorber_jax_planted") == ["Final.hook (Base)"]
