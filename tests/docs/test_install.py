"""The README's install (`pip install -e .`, no extra) holds every library servobus imports,
so every command the README shows runs after it (issue 32, item 2: `servobus serve` once
needed the `[gateway]` extra). Checked on the source: each module a servobus file imports,
unless the import is optional (inside ``try`` ... ``except ImportError``), must come from a
distribution that the default dependencies pull in."""

from __future__ import annotations

import ast
import functools
import re
import sys
import tomllib
from importlib import metadata
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent.parent.parent


def _optional_lines(tree: ast.AST) -> set[int]:
    """Lines of imports inside a try whose handlers catch ImportError."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try) and any(
                "ImportError" in ast.unparse(h.type or ast.Name("BaseException"))
                or "ModuleNotFoundError" in ast.unparse(h.type or ast.Name("x"))
                for h in node.handlers):
            for inner in node.body:
                lines.update(range(inner.lineno, (inner.end_lineno or inner.lineno) + 1))
    return lines


IMPORT = re.compile(r"^[ \t]*(?:import|from)[ \t]+([A-Za-z_]\w*)", re.M)


@functools.cache
def imported_modules() -> dict[str, tuple[Path, ...]]:
    """Top-level third-party module -> the files that import it (a quick textual pass;
    ``required_imports`` then reads the few files that matter with ast)."""
    found: dict[str, list[Path]] = {}
    for path in sorted((ROOT / "servobus").rglob("*.py")):
        for top in set(IMPORT.findall(path.read_text(encoding="utf-8"))):
            if top != "servobus" and top not in sys.stdlib_module_names:
                found.setdefault(top, []).append(path)
    return {module: tuple(paths) for module, paths in found.items()}


def required_imports(module: str, paths: tuple[Path, ...]) -> list[str]:
    """The files that import ``module`` outside a ``try`` that catches ImportError."""
    where: list[str] = []
    for path in paths:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        optional = _optional_lines(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            if node.lineno not in optional and module in {n.split(".")[0] for n in names}:
                where.append(str(path.relative_to(ROOT)))
                break
    return where


def _name(requirement: str) -> str:
    return re.split(r"[\s<>=!~;\[(]", requirement, maxsplit=1)[0].lower().replace("_", "-")


@functools.cache
def default_closure() -> frozenset[str]:
    """The distributions `pip install .` installs: the default dependencies and theirs."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    todo = [_name(r) for r in project["dependencies"]]
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for text in metadata.requires(name) or []:
            requirement = Requirement(text)
            if requirement.marker is None or requirement.marker.evaluate({"extra": ""}):
                todo.append(_name(text))
    return frozenset(seen)


def provided_modules(distributions: frozenset[str]) -> set[str]:
    """The top-level modules those distributions install."""
    modules: set[str] = set()
    for name in distributions:
        for file in metadata.distribution(name).files or []:
            top = file.parts[0]
            if not top.endswith((".dist-info", ".data", ".pth")) and top != "..":
                modules.add(top.removesuffix(".py").split(".")[0])
    return modules


def test_the_default_install_holds_every_library_servobus_imports() -> None:
    provided = provided_modules(default_closure())
    missing = {module: where for module, paths in imported_modules().items()
               if module not in provided and (where := required_imports(module, paths))}
    assert not missing, f"imported, not in the default install (pyproject dependencies): {missing}"


def test_serve_is_among_them() -> None:
    """The case issue 32 found: serve's OPC UA and MQTT libraries."""
    modules = imported_modules()
    assert {"asyncua", "aiomqtt"} <= modules.keys()
    assert {"asyncua", "aiomqtt"} <= default_closure()


def test_serve_without_its_libraries_names_the_install_command() -> None:
    """An environment installed otherwise (--no-deps): the pip command, never "a bug"."""
    from servobus.cli.failures import describe
    from servobus.cli.serve_cmd import _missing_library

    code, line = describe(_missing_library(ModuleNotFoundError("no aiomqtt", name="aiomqtt")))
    assert code == 2
    assert "'aiomqtt'" in line and "-m pip install asyncua aiomqtt" in line
    assert "bug" not in line
    other = ModuleNotFoundError("no foo", name="foo")
    assert _missing_library(other) is other  # anything else stays what it is
