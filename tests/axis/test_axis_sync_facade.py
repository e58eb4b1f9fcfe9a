"""The sync Axis is an explicit typed facade over AsyncAxis (issue 19): these checks fail
when the two drift apart - a method added to one and not the other, or a parameter, a
default or a type that differs."""

from __future__ import annotations

import inspect
from collections.abc import Iterator

import pytest

from servobus.axis import AsyncAxis, Axis, connect

#: AsyncAxis members the facade leaves out on purpose, and why.
NOT_ON_THE_FACADE = {
    "capture_source": "wiring the simulator sets on the core (trace_buffer() reads it)",
    "io_source": "wiring the simulator sets on the core (virtual_io() reads it)",
    "unsupported": "a helper for protocol implementations, not for callers",
    "protocol_capabilities": "a protocol's declaration; callers ask ``capabilities``",
}
#: Facade members AsyncAxis has not: the way to the core and to a protocol's extras.
FACADE_ONLY = {"core", "extra"}
#: The async and sync names of the same thing.
ASYNC_TO_SYNC = {"__aenter__": "__enter__", "__aexit__": "__exit__"}


def public(cls: type) -> set[str]:
    return {n for n in dir(cls) if not n.startswith("_")}


def shape(member: object, *, sync_result: bool = False) -> tuple[object, ...]:
    """Parameters (name, kind, default, annotation) and the result annotation, with the
    async names mapped to the sync ones."""
    signature = inspect.signature(member)  # type: ignore[arg-type]
    def sync(annotation: object) -> object:  # an AsyncAxis in a sync call is an Axis
        return annotation.replace("AsyncAxis", "Axis") if sync_result and isinstance(
            annotation, str) else annotation

    return (tuple((p.name, p.kind, p.default, sync(p.annotation))
                  for p in signature.parameters.values()),
            sync(str(signature.return_annotation)))


def test_every_axis_method_is_on_the_facade_and_nothing_else() -> None:
    expected = (public(AsyncAxis) - set(NOT_ON_THE_FACADE)) | FACADE_ONLY
    assert public(Axis) == expected


@pytest.mark.parametrize("name", sorted(public(AsyncAxis) - set(NOT_ON_THE_FACADE))
                         + sorted(ASYNC_TO_SYNC))
def test_the_facade_has_the_same_signature(name: str) -> None:
    core = inspect.getattr_static(AsyncAxis, name)
    facade = inspect.getattr_static(Axis, ASYNC_TO_SYNC.get(name, name))
    if isinstance(core, property):
        assert isinstance(facade, property), name
        assert shape(facade.fget) == shape(core.fget)
        return
    if isinstance(core, bool):  # a plain attribute of the core (continuous): a read property
        assert isinstance(facade, property), name
        assert shape(facade.fget)[1] == "bool", name
        return
    assert callable(core) and callable(facade), name
    assert not inspect.iscoroutinefunction(facade), f"Axis.{name} must block, not be async"
    if name in ASYNC_TO_SYNC:  # __enter__/__exit__: the same result, their own parameters
        assert shape(facade)[1] == shape(core, sync_result=True)[1]
        return
    assert shape(facade) == shape(core, sync_result=inspect.iscoroutinefunction(core)), name


@pytest.fixture
def axis() -> Iterator[Axis]:
    with connect("sim://dyn232?fast=1", drive_id=1, timeout=0.2) as ax:
        yield ax


def test_extras_run_synchronously(axis: Axis) -> None:
    """A protocol's own coroutine (DYN232M's drive config) runs like the Axis methods."""
    config = axis.extra.config()
    assert config.as_dict() == axis.extra.config().as_dict()
    assert axis.extra.protocol_name == "dyn232"  # plain attributes are read through
    assert "config" in dir(axis.extra)


def test_an_unknown_extra_is_an_attribute_error(axis: Axis) -> None:
    with pytest.raises(AttributeError):
        axis.extra.move_too(5)
    with pytest.raises(AttributeError):
        axis.move_too(5)  # type: ignore[attr-defined]


def test_a_protocol_method_is_reached_through_extra_only(axis: Axis) -> None:
    """The one-release ``axis.config()`` fallback went with issue 31: ``axis.extra``."""
    with pytest.raises(AttributeError):
        axis.config()  # type: ignore[attr-defined]
    assert axis.extra.config().as_dict()
