"""What a type checker sees of the public API (issue 19): ``connect()`` returns a typed
``Axis``, its reads have their types, a misspelt method is an error, and the README's
Python example passes ``mypy --strict``.

One mypy run (its API, in-process) checks every snippet below; its cache lives in a
temporary directory, so the run is cold (about 3 s on 2 cores, once per session).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import servobus

mypy_api = pytest.importorskip("mypy.api", reason="mypy is in the test extra")

ROOT = Path(servobus.__file__).parent.parent
README = ROOT / "README.md"

SNIPPETS = {
    "revealed": """
        from servobus import connect, connect_async

        axis = connect("sim://dyn232")
        reveal_type(axis.position())
        reveal_type(axis.status())
        reveal_type(axis.read_params())
        reveal_type(axis.sibling(2))
        reveal_type(axis.extra)

        async def main() -> None:
            core = await connect_async("sim://dyn232")
            reveal_type(await core.position())
        """,
    "misspelt": """
        import servobus
        from servobus import connect

        with connect("sim://dyn232") as axis:
            axis.move_too(5)
        servobus.conect("sim://dyn232")
        """,
    "extras": """
        from servobus import connect

        with connect("sim://dyn232") as axis:
            axis.extra.config()
            axis.move_to(axis.revs(1), wait=True, confirm=True)
        """,
}


def readme_python() -> str:
    """The first ```python block of the README's "## Python" section."""
    text = README.read_text(encoding="utf-8")
    section = text.split("\n## Python\n", 1)[1]
    match = re.search(r"```python\n(.*?)```", section, re.S)
    assert match, "README: no python block under ## Python"
    return match.group(1)


@pytest.fixture(scope="module")
def checked(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """mypy --strict over every snippet (and the README's example): lines per snippet."""
    work = tmp_path_factory.mktemp("typing")
    sources = {name: "\n".join(line[8:] for line in code.splitlines()).strip() + "\n"
               for name, code in SNIPPETS.items()}
    if README.is_file():
        sources["readme"] = readme_python()
    for name, code in sources.items():
        (work / f"{name}.py").write_text(code, encoding="utf-8")
    config = work / "mypy.ini"
    in_tree = (ROOT / "pyproject.toml").is_file()  # a checkout: servobus is found from here
    config.write_text("[mypy]\nstrict = True\n"
                      + (f"mypy_path = {ROOT}\n" if in_tree else "")
                      + "[mypy-serial.*,can.*]\nignore_missing_imports = True\n",
                      encoding="utf-8")
    out, err, _ = mypy_api.run(["--config-file", str(config), "--cache-dir",
                                str(work / "cache"), "--no-error-summary",
                                *(str(work / f"{name}.py") for name in sources)])
    assert not err, err
    lines: dict[str, list[str]] = {name: [] for name in sources}
    for line in out.splitlines():
        name = Path(line.split(":", 1)[0]).stem
        lines.setdefault(name, []).append(line.split(": ", 1)[1] if ": " in line else line)
    return lines


def test_connect_returns_a_typed_axis(checked: dict[str, list[str]]) -> None:
    assert checked["revealed"] == [
        'note: Revealed type is "int"',
        'note: Revealed type is "servobus.axis.types.AxisStatus"',
        'note: Revealed type is "dict[str, int]"',
        'note: Revealed type is "servobus.axis.sync.Axis"',
        'note: Revealed type is "Any"',
        'note: Revealed type is "int"',
    ]


def test_a_misspelt_method_is_a_type_error(checked: dict[str, list[str]]) -> None:
    errors = checked["misspelt"]
    assert any('"Axis" has no attribute "move_too"' in e for e in errors), errors
    assert any('has no attribute "conect"' in e for e in errors), errors


def test_protocol_extras_are_reachable_through_extra(checked: dict[str, list[str]]) -> None:
    assert checked["extras"] == []


def test_the_readme_example_type_checks(checked: dict[str, list[str]]) -> None:
    if "readme" not in checked:
        pytest.skip("README.md is not beside the installed package")
    assert checked["readme"] == []
