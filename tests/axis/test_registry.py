"""The registry reads one frozen ProtocolSpec per protocol package (issue 19): every
``module:attribute`` it names resolves, every package declares one, and the tables the
shared layers read are derived from the specs."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

from servobus import families
from servobus.axis import registry
from servobus.axis.cli_spec import Command
from servobus.axis.url import parse_url
from servobus.protocols import ProtocolSpec

PACKAGES = sorted(p.name for p in Path(registry.importlib.import_module(
    registry.PROTOCOL_PACKAGE).__path__[0]).iterdir() if (p / "__init__.py").is_file())
SPECS = registry.specs()


def targets(spec: ProtocolSpec) -> dict[str, str]:
    return {f: v for f in ("opener", "sim", "cli", "decoder", "params")
            if isinstance(v := getattr(spec, f), str)}


def test_every_protocol_package_declares_one_spec() -> None:
    assert PACKAGES and sorted(SPECS) == PACKAGES
    for name, spec in SPECS.items():
        assert isinstance(spec, ProtocolSpec) and spec.name == name
        with pytest.raises(dataclasses.FrozenInstanceError):
            spec.name = "other"  # type: ignore[misc]


def test_no_loose_tables_beside_the_spec() -> None:
    for name in PACKAGES:
        module = registry.importlib.import_module(f"{registry.PROTOCOL_PACKAGE}.{name}")
        loose = {"SCHEMES", "SIM", "CLI", "DECODERS", "PARAMS", "FAMILIES", "SHORTCUTS"}
        assert loose & set(vars(module)) == set(), name


@pytest.mark.parametrize("name", sorted(SPECS))
def test_every_target_resolves(name: str) -> None:
    spec = SPECS[name]
    found = targets(spec)
    assert {"opener", "sim", "cli", "decoder", "params"} <= set(found)
    for field, target in found.items():
        assert target.count(":") == 1, (field, target)
        value = registry.load(target)
        if field in ("opener", "sim"):
            assert inspect.iscoroutinefunction(value), (field, target)
        elif field == "cli":
            assert value and all(isinstance(c, Command) for c in value), target
        elif field == "params":
            assert len(tuple(value)) > 0 and all(isinstance(n, str) for n in value), target
        else:
            assert value is not None, target
    assert families.family(spec.family).name == spec.family


def test_schemes_and_sim_names_belong_to_one_protocol() -> None:
    schemes = [s for spec in SPECS.values() for s in spec.schemes]
    sims = [n for spec in SPECS.values() for n in spec.sim_names]
    assert len(schemes) == len(set(schemes)) and len(sims) == len(set(sims))
    assert "sim" not in schemes  # the simulator's scheme


def test_the_shared_tables_come_from_the_specs() -> None:
    for spec in SPECS.values():
        assert {registry.provided("SCHEMES")[s] for s in spec.schemes} == {spec.opener}
        assert {registry.provided("SIM")[n] for n in spec.sim_names} == {spec.sim}
        assert registry.provided("DECODERS")[spec.name] == spec.decoder
        assert registry.provided("FAMILIES")[spec.name] == spec.family
    assert registry.provided_list("CLI") == [s.cli for s in SPECS.values()]
    assert registry.provided("SHORTCUTS")["can"] == "dyncan+{interface}://{channel}"


def test_a_protocol_package_loads_no_codec_or_client() -> None:
    """Importing every protocol package (what the registry does) loads the spec only."""
    code = ("import sys, servobus.axis.registry as r; r.specs(); "
            "print(sorted(m for m in sys.modules if m.startswith('servobus.protocols.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout
    assert ast.literal_eval(out) == [f"servobus.protocols.{name}" for name in PACKAGES]


@pytest.mark.parametrize(("url", "inline"), [
    ("enip://192.168.50.18", True), ("socket://127.0.0.1:4001", True),
    ("tcp://127.0.0.1:4001", True), ("sim://dyn232", False), ("sim://enip", False),
    ("/dev/ttyUSB0", False), ("dyn232+socket://127.0.0.1:4001", False),
    ("dyncan+virtual://bus", False), ("easycan+virtual://bus", False),
    ("modbus:///dev/ttyUSB0", False)])
def test_which_links_run_inline(url: str, inline: bool) -> None:
    """Issue 22: the protocols name the schemes whose axes need no loop between calls."""
    assert registry.runs_inline(parse_url(url)) is inline


def test_sim_is_the_registrys_own_scheme() -> None:
    """Issue 31: no provider declares loose tables any more, the simulator neither."""
    assert registry.schemes()["sim"] == registry.BUILTIN_SCHEMES["sim"]
    assert "sim" in registry.own_schemes()
    assert not hasattr(registry.importlib.import_module("servobus.sim.schemes"), "SCHEMES")


def test_a_provider_without_a_spec_is_skipped_with_one_warning(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    modules = registry._provider_modules()
    monkeypatch.setattr(registry, "_provider_modules", lambda: [*modules, "servobus.errors"])
    monkeypatch.setattr(registry, "_specs", None)
    monkeypatch.setattr(registry, "_tables", {})
    assert registry.specs() == SPECS
    assert registry.provided("FAMILIES") == {n: s.family for n, s in SPECS.items()}
    assert [r.getMessage() for r in caplog.records] == [
        "servobus provider servobus.errors declares no ProtocolSpec SPEC: skipped"]
