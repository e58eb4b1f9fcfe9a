"""The Tuning tab's "Auto": the tuner (servobus.tune, the CLI's ``servobus tune``) run on
one axis, owned by the page that started it.

Decisions (docs/gui.md, "Auto-tune"):

* The run is the machine axis's :meth:`~servobus.machine.axis.AsyncMachineAxis.tune`, as the
  CLI's: the soft limits are checked before anything moves, the kept gains come back on an
  abort, a failure or a cancel, and while it runs the machine refuses every other motion of
  the axis and Stop (the axis's, STOP ALL, the shutdown's) cancels it. The checks and words
  before it are :mod:`servobus.tune.plan`'s, the CLI's.
* The owner is the page (``page N``, as a jog, servobus.gui.jog). One run per axis. The page
  renews the run over its WebSocket (``tune_renew`` every 150 ms, like a jog); a run not
  renewed for the GUI's lease (:data:`servobus.gui.jog.LEASE_S`, 0.5 s) is cancelled, and
  so is every run of a page whose WebSocket closes (:meth:`AutoTune.release`): the tuner's
  abort stops the motor at once and writes the kept gains back.
* Start is two requests: ``confirmed: false`` checks everything and returns the question
  naming the axis and the distance in the axis's unit (nothing moves), ``confirmed: true``
  starts. Figures and errors are shown in the axis's unit.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from dataclasses import dataclass, field

from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    OwnerError,
    ServobusError,
    TuningInterrupted,
)
from servobus.gui.fleet import AxisHandle
from servobus.gui.jog import LEASE_S, page_owner
from servobus.machine.axis import AsyncMachineAxis
from servobus.tune import plan
from servobus.tune.tuner import Trial, TuneResult

log = logging.getLogger(__name__)

#: How often the watchdog looks at a run's renewal, seconds.
WATCH_S = 0.1
#: Test moves shown as progress (a run makes about 20 - 40).
MAX_TRIALS_SHOWN = 80


@dataclass
class AutoRun:
    """One run on one axis: its owner, its progress, how it ended."""

    axis: int
    owner: str
    who: str
    distance: str  # as shown: the value and the axis's unit
    per_count: float  # the axis's shown unit per count (following errors)
    unit: str
    deadline: float
    goal: str = "settling"  # servobus.tune.tuner.GOALS
    state: str = "running"  # running, done, stopped, failed
    message: str = ""
    trials: list[Trial] = field(default_factory=list)
    result: TuneResult | None = None
    reverted: bool = False
    #: Refused because a killed run left its kept gains (servobus.tune.kept): Revert
    #: writes those back.
    restorable: bool = False
    task: asyncio.Task[None] | None = None
    why_cancelled: str = ""

    def add(self, trial: Trial) -> None:
        if len(self.trials) < MAX_TRIALS_SHOWN:
            self.trials.append(trial)

    def _figures(self, trial: Trial) -> dict[str, object]:
        fe = trial.following_error
        return {"rise_s": trial.rise_s, "overshoot_pct": trial.overshoot_pct,
                "settling_s": trial.settling_s,
                "following_error": None if fe is None else fe * abs(self.per_count),
                "vibration": trial.vibration}

    def view(self, mine: str) -> dict[str, object]:
        """What the page shows: progress while it runs, the table when done."""
        last = self.trials[-1] if self.trials else None
        doc: dict[str, object] = {
            "axis": self.axis, "owner": self.owner, "mine": self.owner == mine,
            "who": self.who, "distance": self.distance, "unit": self.unit,
            "state": self.state, "message": self.message, "goal": self.goal,
            "phase": last.phase if last is not None else "starting",
            "trials": len(self.trials),
            "tried": [{"phase": t.phase, "gains": t.gains,
                       "vibration": _finite(t.vibration),
                       "overshoot_pct": _finite(t.overshoot_pct)} for t in self.trials[-8:]],
            "max_vibration": _finite(max((t.vibration for t in self.trials), default=0.0)),
            "reverted": self.reverted, "restorable": self.restorable}
        r = self.result
        if r is not None:
            doc["result"] = {
                "before": {k: _finite(v) for k, v in self._figures(r.before).items()},
                "after": {k: _finite(v) for k, v in self._figures(r.after).items()},
                "gains": [{"name": n, "kept": kept, "tuned": r.tuned[n],
                           "vibrated_at": r.limits_found.get(n)}
                          for n, kept in r.original.items()],
                "trials": r.trials, "writes": r.writes, "source": r.source,
                "rate_hz": r.rate_hz, "inertia_ratio": _finite(r.inertia_ratio),
                "saved": r.saved, "persistence": r.persistence, "save_hint": r.save_hint}
        return doc


def _finite(value: object) -> object:
    return None if isinstance(value, float) and not math.isfinite(value) else value


class AutoTune:
    """Every axis's Auto run (the last one is kept for its table and Revert)."""

    def __init__(self, lease_s: float = LEASE_S) -> None:
        self.lease_s = lease_s
        self.runs: dict[int, AutoRun] = {}
        self.closed = False

    # ------------------------------------------------------------- from a page
    async def check(self, handle: AxisHandle, page: int, value: float, unit: str,
                    save: bool) -> tuple[int, str, str]:
        """(counts, who, shown) of a run of ``value`` (the axis's shown unit) by ``page``,
        checked before anything moves: the owner, one run per axis, ``save``, the soft
        limits; typed errors in the axis's unit."""
        m = self._machine_axis(handle)
        if self.closed:
            raise ConnectionLost("the GUI is shutting down: every axis is being stopped")
        self._check_one_run(handle)
        units = handle.units()
        if unit != units.position:
            raise ArgumentRangeError(f"{handle.label}: the distance is in {units.position}, "
                                     f"not {unit}")
        counts = handle.to_counts(value)
        if counts == 0:
            raise ArgumentRangeError(f"{handle.label}: a distance of {value:g} "
                                     f"{units.position} is less than one count; nothing was "
                                     "moved")
        plan.check_save(handle.axis.family.tuning, handle.axis.family.title, save)
        m.check_owner(page_owner(page))
        here = await handle.call(m.counts())
        m.check_target(m.to_user(here + counts))  # LimitError in the axis's unit
        return counts, handle.label, f"{value:g} {units.position}"

    async def ask(self, handle: AxisHandle, page: int, value: float, unit: str,
                  save: bool) -> dict[str, object]:
        """The confirmation (nothing moves): the question, the EEPROM note, the save hint."""
        _counts, who, shown = await self.check(handle, page, value, unit, save)
        profile = handle.axis.family.tuning
        return {"question": plan.question(who, shown), "note": plan.write_note(profile),
                "save_hint": profile.save_hint if profile is not None else "",
                "can_save": plan.saves_with_command(profile), "distance": shown}

    async def start(self, handle: AxisHandle, page: int, value: float, unit: str,
                    save: bool, *, goal: str = "settling") -> AutoRun:
        counts, who, shown = await self.check(handle, page, value, unit, save)
        m = self._machine_axis(handle)
        owner = page_owner(page)
        self._check_one_run(handle)  # again: another may have started while this one checked
        units = handle.units()
        run = AutoRun(handle.id, owner, who, shown, units.per_count, units.position,
                      time.monotonic() + self.lease_s, goal=goal)
        self.runs[handle.id] = run
        run.task = asyncio.create_task(self._run(run, handle, m, counts, save, goal),
                                       name=f"auto-tune {handle.label}")
        log.info("%s: auto-tune started by %s (test moves of %s)", who, owner, shown)
        return run

    def renew(self, page: int, axis_id: int) -> None:
        """The page still shows its run: keep it alive another ``lease_s``."""
        run = self.runs.get(axis_id)
        if run is None or run.state != "running":
            return  # ended: the status tells the page how
        if run.owner != page_owner(page):
            raise OwnerError(f"{run.who}: the auto-tune run is {run.owner}'s, not this "
                             "page's", owner=run.owner)
        run.deadline = time.monotonic() + self.lease_s

    async def cancel(self, axis_id: int, why: str) -> AutoRun | None:
        """Abort the axis's run (stop, kept gains back) and wait for it; Stop always wins,
        so any page may cancel."""
        run = self.runs.get(axis_id)
        if run is None or run.task is None or run.task.done():
            return run
        run.why_cancelled = why
        run.task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await run.task
        return run

    async def release(self, page: int) -> None:
        """The page went away: each of its runs is cancelled."""
        owner = page_owner(page)
        for axis_id, run in list(self.runs.items()):
            if run.owner == owner and run.state == "running":
                await self.cancel(axis_id, "the page that ran it went away")

    async def revert(self, handle: AxisHandle) -> dict[str, int]:
        """The last run's kept gains back (the machine axis writes only what differs); after
        a run refused for a killed run's record, that run's kept gains (restore_gains)."""
        run = self.runs.get(handle.id)
        m = self._machine_axis(handle)
        if run is not None and run.restorable and run.state != "running":
            written = await handle.call(m.restore_gains())
            run.restorable = False
            run.reverted = True
            log.info("%s: a killed run's kept gains restored (%d written)", run.who,
                     len(written))
            return written
        if run is None or run.result is None:
            raise ArgumentRangeError(f"{handle.label}: no finished auto-tune run to revert")
        written = await handle.call(m.revert_gains(run.result.original))
        run.reverted = True
        log.info("%s: auto-tuned gains reverted (%d written)", run.who, len(written))
        return written

    async def stop(self) -> None:
        """Shutdown: no new run; every run cancelled (the axes were stopped before)."""
        self.closed = True
        for axis_id in list(self.runs):
            await self.cancel(axis_id, "the GUI is shutting down")

    def views(self, page: int) -> dict[str, dict[str, object]]:
        mine = page_owner(page)
        return {str(k): r.view(mine) for k, r in self.runs.items()}

    # ------------------------------------------------------------- inside
    def _check_one_run(self, handle: AxisHandle) -> None:
        run = self.runs.get(handle.id)
        if run is not None and run.state == "running":
            raise OwnerError(f"{handle.label}: {run.owner} is auto-tuning it; one run per "
                             "axis, nothing was moved", owner=run.owner)

    def _machine_axis(self, handle: AxisHandle) -> AsyncMachineAxis:
        m = handle.machine_axis
        if m is None:
            raise ArgumentRangeError(f"{handle.label} has no machine axis: no auto-tune")
        return m

    async def _run(self, run: AutoRun, handle: AxisHandle, m: AsyncMachineAxis, counts: int,
                   save: bool, goal: str) -> None:
        watchdog = asyncio.create_task(self._watch(run))
        try:
            run.result = await handle.call(m.tune(counts, owner=run.owner, save=save,
                                                  goal=goal, on_trial=run.add))
            run.state = "done"
            run.message = "tuned" + ("; saved" if run.result.saved else "")
        except asyncio.CancelledError:
            run.state = "stopped"
            why = run.why_cancelled or "stopped"
            run.message = f"{why}: the motor was stopped and the kept gains written back"
        except ServobusError as exc:
            run.state = "failed"
            run.message = f"{type(exc).__name__}: {exc}"
            if isinstance(exc, TuningInterrupted):
                run.restorable = True
                run.message += " (Revert writes them back)"
        except Exception as exc:  # this run's boundary: a bug ends the run, not the GUI
            run.state = "failed"
            run.message = f"internal error ({type(exc).__name__}): {exc}"
            log.debug("auto-tune failed", exc_info=True)
        finally:
            watchdog.cancel()
        log.info("%s: auto-tune %s: %s", run.who, run.state, run.message)

    async def _watch(self, run: AutoRun) -> None:
        """Cancel the run when its page stops renewing it (a frozen tab). A lapse is looked
        at again one period later: a loop that was busy reads the renewals queued meanwhile
        first (at most ``lease_s`` + 2 periods from the last renewal to the stop)."""
        while True:
            await asyncio.sleep(WATCH_S)
            if time.monotonic() <= run.deadline:
                continue
            await asyncio.sleep(WATCH_S)
            if time.monotonic() > run.deadline and run.task is not None:
                run.why_cancelled = "the page stopped renewing the run"
                run.task.cancel()
                return
