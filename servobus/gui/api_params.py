"""REST: the Parameters panel (table, write, backup download, restore/diff upload) and
the Tuning panel (step test, gains apply/revert).

Backups are the file of ``servobus params --save`` (servobus.families.params_file), so a file
saved here loads on the command line and back. A restore first shows what would change
(``apply: false``: a diff against the drive, with the EEPROM writes it would cost), then
writes only the values that differ and reads them back.
"""

from __future__ import annotations

from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from servobus.axis.types import ParamInfo, Storage
from servobus.axis.units import to_counts
from servobus.errors import ArgumentRangeError
from servobus.families import params_file as PF
from servobus.gui import tuning
from servobus.gui.fleet import AxisHandle
from servobus.gui.http_util import api, body, handle, integer, number, ok, state
from servobus.gui.soft_limits import check_not_tuning


def describe(p: ParamInfo) -> dict[str, object]:
    return {"name": p.name, "minimum": p.minimum, "maximum": p.maximum, "default": p.default,
            "unit": p.unit, "storage": p.storage.value, "doc": p.doc}


def eeprom_writes(h: AxisHandle, names: list[str]) -> int:
    return sum(h.axis.param_info(n).storage is Storage.EEPROM for n in names)


def _values(doc: dict[str, object], key: str = "values") -> dict[str, int]:
    raw = doc.get(key)
    if not isinstance(raw, dict) or not raw:
        raise ArgumentRangeError(f"'{key}' must be a non-empty object of name: integer")
    out: dict[str, int] = {}
    for name, value in raw.items():
        if isinstance(value, bool) or not isinstance(value, int):
            raise ArgumentRangeError(f"{name} must be an integer, got {value!r}")
        out[str(name)] = value
    return out


@api
async def params(request: Request) -> Response:
    h = handle(request)
    values = await h.call(h.axis.read_params())
    return JSONResponse({"axis": h.id, "family": h.axis.family.name,
                         "protocol": h.axis.protocol,
                         "params": [{**describe(p), "value": values[p.name]}
                                    for p in h.axis.parameters()]})


@api
async def write_params(request: Request) -> Response:
    h = handle(request)
    values = _values(await body(request))
    check_not_tuning(h, "writing parameters")
    for name, value in values.items():
        h.axis.param_info(name).check(value)  # all checked before the first write
    await h.call(h.axis.write_params(values))
    after = await h.call(h.axis.read_params(list(values)))
    return ok(values=after, eeprom_writes=eeprom_writes(h, list(values)),
              failed=[n for n, v in values.items() if after[n] != v])


@api
async def backup(request: Request) -> Response:
    h = handle(request)
    values = await h.call(h.axis.read_params())
    doc = PF.ParamsBackup(h.axis.protocol, h.axis.drive_id, dict(values),
                          h.axis.family.name).to_json()
    name = f"servobus-axis{h.id}-{h.axis.family.name}.json"
    return JSONResponse(doc, headers={"Content-Disposition": f'attachment; filename="{name}"'})


@api
async def restore(request: Request) -> Response:
    h = handle(request)
    doc = await body(request)
    apply = bool(doc.get("apply", False))
    saved = PF.parse(doc.get("backup"), "the uploaded file")
    if saved.family != h.axis.family.name:
        raise ArgumentRangeError(f"the file holds {saved.family} parameters; {h.label} is "
                                 f"{h.axis.family.name}")
    names = list(saved.params)
    for n in names:
        h.axis.param_info(n)  # every name reachable before anything is written
    before = await h.call(h.axis.read_params(names))
    changes = PF.diff(saved.params, before)
    after = before
    if apply and changes:
        await h.call(h.axis.write_params({n: wanted for n, wanted, _ in changes}))
        after = await h.call(h.axis.read_params(names))
    return ok(applied=apply, saved_from=saved.drive_id, protocol=saved.protocol,
              changes=len(changes),
              eeprom_writes=eeprom_writes(h, [n for n, _, _ in changes]),
              rows=[{"name": n, "file": saved.params[n], "drive": before[n], "after": after[n],
                     "storage": h.axis.param_info(n).storage.value} for n in names],
              failed=[n for n, _, _ in PF.diff(saved.params, after)] if apply else [])


@api
async def tuning_state(request: Request) -> Response:
    h = handle(request)
    st = state(request).tuning[h.id]
    names = tuning.gain_names(h)
    values = await h.call(h.axis.read_params(names)) if names else {}
    return JSONResponse({"gains": [{**describe(h.axis.param_info(n)), "value": values[n]}
                                   for n in names],
                         "results": list(st.results), "can_revert": bool(st.previous),
                         "previous": st.previous})


@api
async def step(request: Request) -> Response:
    h = handle(request)
    gui = state(request)
    doc = await body(request)
    value, unit = number(doc, "distance"), str(doc.get("unit", "counts"))
    units = h.units()
    distance = h.to_counts(value) if unit == units.position \
        else to_counts(value, unit, h.axis.counts_per_rev)
    result = await tuning.run_step(h, gui.samplers[h.id], gui.tuning[h.id], distance,
                                   number(doc, "duration_s", 1.0))
    return JSONResponse(result)


@api
async def apply_gains(request: Request) -> Response:
    h = handle(request)
    before = await tuning.apply_gains(h, state(request).tuning[h.id],
                                      _values(await body(request)))
    return ok(previous=before)


@api
async def revert_gains(request: Request) -> Response:
    h = handle(request)
    await body(request)
    values = await tuning.revert_gains(h, state(request).tuning[h.id])
    return ok(restored=values)


@api
async def clear_results(request: Request) -> Response:
    h = handle(request)
    n = integer(await body(request), "keep", 0)
    results = state(request).tuning[h.id].results
    while len(results) > max(0, n):
        results.popleft()
    return ok()


ROUTES = [
    Route("/api/axes/{axis}/params", params),
    Route("/api/axes/{axis}/params", write_params, methods=["POST"]),
    Route("/api/axes/{axis}/params/backup", backup),
    Route("/api/axes/{axis}/params/restore", restore, methods=["POST"]),
    Route("/api/axes/{axis}/tuning", tuning_state),
    Route("/api/axes/{axis}/tuning/step", step, methods=["POST"]),
    Route("/api/axes/{axis}/tuning/apply", apply_gains, methods=["POST"]),
    Route("/api/axes/{axis}/tuning/revert", revert_gains, methods=["POST"]),
    Route("/api/axes/{axis}/tuning/clear", clear_results, methods=["POST"]),
]
