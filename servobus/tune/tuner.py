"""The manuals' tuning procedure (DYN2 5.2; YZ-AIM 5.2 gains), run against a Plant.

Procedure (docs/tuning.md, "The tuner"):

1. read and keep the gains; a test move at them (the *before* figures) doubles as the
   inertia test: the current over the acceleration gives the load's inertia ratio where
   the plant knows its rotor (:func:`inertia_ratio`); where they vibrate, calm them first;
2. at the first calm gains, let the drive learn (:meth:`Tuner._learn`): test moves until
   :data:`LEARN_AGREE` in a row are :func:`alike` (DMM Adaptive Tuning learns the load
   over the moves; gains compared while it learns are compared on different machines);
   goal "settling" on a drive that learns its load (:meth:`Tuner._soften`): after
   :data:`LEARN_MOVES` moves in all, the loop softer as a whole, kept where it settles
   clearly faster (goal "stiffness" skips it: the stiff gains give less under a load step);
3. for each gain role in :data:`ORDER` (speed, position, integral, filter): raise it along
   :func:`candidates` with a test move each, until the move vibrates or rings
   (:data:`DETECT`); back off: only values within :data:`MARGIN` of the first vibrating
   one count; keep the one of those that settles fastest within :data:`MAX_OVERSHOOT_PCT`
   (:func:`pick`: ties within :data:`SETTLE_NOISE` go to the value nearest the start).
   Where that is the start itself, or it vibrates or overshoots, try the other way too;
4. fine tuning (5.2: "make the motor harder ... or softer"), on a drive trace only: each
   gain in turn one :data:`FINE` step harder, else softer, kept while the move gets clearly
   better (:meth:`Trial.improves_on`) and stays below the onset of vibration; half
   steps, then quarter steps. Its margin is that step, not :data:`MARGIN`: a kept value
   may lie one half step below one that vibrated at other gains;
5. a last test move at the tuned gains (the *after* figures).

Safety: the first move beyond the :class:`Limits` (soft limits, the distance the user gave)
is refused before anything moves; an alarm, a vibration beyond ``vibration_limit``, a
failure or a cancel (Ctrl-C) stops the motor and writes the kept gains back. A gain is
written only when it changes; on EEPROM families the run keeps a write budget
(:data:`EEPROM_WRITE_BUDGET`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from servobus.axis.types import GainRole, Persistence, TuningGain
from servobus.errors import ServobusError
from servobus.tune.plant import Plant
from servobus.tune.record import Record, vibration

ORDER = (GainRole.SPEED, GainRole.POSITION, GainRole.INTEGRAL, GainRole.FILTER)
#: Vibration (servobus.tune.record) from which a test move counts as vibrating or ringing.
DETECT = 0.05
#: The search stops raising a gain at half that: the onset of vibration is its limit.
ONSET = DETECT / 2
#: Default abort limit: a hold current swinging this much of the move's peak is loud.
ABORT_VIBRATION = 1.5
#: Back-off: a gain may be at most this fraction of the first vibrating value (3 dB).
MARGIN = 0.7
MAX_OVERSHOOT_PCT = 10.0
#: Each step up multiplies a gain by this much (fewer steps: fewer EEPROM writes).
RAISE = 1.4
#: Fine tuning's steps: half the search's (in dB), between the values the search tried,
#: then a quarter.
FINE = (math.sqrt(RAISE), math.sqrt(math.sqrt(RAISE)))
#: DMM: the EEPROM guard warns past 10 writes of one parameter a minute and refuses past 30
#: (servobus.link.eeprom_guard); 10 a gain, the revert included, keeps a run under both and
#: 40 a run is 25,000 runs from the drive's million-cycle life.
EEPROM_WRITES_PER_GAIN = 10
EEPROM_WRITE_BUDGET = 40
RECORD_S = 0.6
#: How long the motor may take to come to rest before a test move (it starts anyway).
SETTLE_TIMEOUT_S = 0.5
#: ... and before the verify move (the *after* figures), which should not inherit the ringing
#: of the search's last move.
VERIFY_SETTLE_S = 2.0
#: Steps a gain is lowered by at most while the kept gains vibrate (the calm phase) and
#: while the best raised value still overshoots (the search's way down).
CALM_STEPS = 4
#: Settling times within this fraction of each other are a tie: one move's settling time
#: varies by a few per cent with the state the move starts from (measured: 228 - 234 ms
#: over six moves at the same gains, YZ-AIM belt at inertia 30).
SETTLE_NOISE = 0.05
#: The drive has learnt (its response stopped changing) when this many test moves in a row
#: at the same gains are :func:`alike`; it gets at most LEARN_MOVES moves for it (measured:
#: a DMM drive's Adaptive Tuning learns the screw at inertia 30 in some 18 quarter turns).
LEARN_AGREE = 3
LEARN_MOVES = 24
LEARN_OVERSHOOT_PP = 1.0
#: Goal "settling" on a drive that learns its load (TuningProfile.learns_load): after the
#: learning moves, the position, speed and integral gains together, each divided by SOFTEN
#: per step (two search steps: each step writes three gains), up to SOFTEN_STEPS steps; the
#: fastest to settle is kept (ties: the stiffer). Goal "stiffness" skips it.
SOFTEN = RAISE * RAISE
SOFTEN_STEPS = 3
SOFTEN_ROLES = (GainRole.POSITION, GainRole.SPEED, GainRole.INTEGRAL)
GOALS = ("settling", "stiffness")
#: Polled samples time a step coarsely: the tuner backs off further from what it cannot see.
POLL_MARGIN = 0.6


class TuneAborted(ServobusError):
    """A tuning run stopped the motor and wrote the kept gains back; the message says why."""


@dataclass(frozen=True)
class Limits:
    """Where test moves may go: ``distance`` counts from the start (its sign the first
    move's direction), inside ``soft_limits`` (counts) when the axis has them. Messages give
    positions in ``unit`` through ``to_user`` (a machine axis's mm, deg ...), else counts."""

    distance: int
    soft_limits: tuple[int, int] | None = None
    vibration_limit: float = ABORT_VIBRATION
    record_s: float = RECORD_S
    to_user: Callable[[int], float] | None = None
    unit: str = "counts"

    def at(self, *counts: int) -> str:
        """Positions in counts as the user reads them, lowest first: ``-10 .. 300 mm``."""
        values = sorted(c if self.to_user is None else self.to_user(c) for c in counts)
        return f"{' .. '.join(f'{v:g}' for v in values)} {self.unit}"


@dataclass(frozen=True)
class Trial:
    gains: dict[str, int]
    overshoot_pct: float
    settling_s: float | None
    rise_s: float | None
    following_error: float | None
    vibration: float
    #: The step of the procedure the move belongs to (:attr:`Tuner.phase`).
    phase: str = ""

    @property
    def vibrates(self) -> bool:
        return self.vibration >= DETECT

    def score(self) -> tuple[bool, bool, float, float]:
        """Smaller is better: calm, within the overshoot, fast to settle, little overshoot."""
        return (self.vibrates, self.overshoot_pct > MAX_OVERSHOOT_PCT,
                math.inf if self.settling_s is None else self.settling_s, self.overshoot_pct)

    def improves_on(self, other: Trial) -> bool:
        """Clearly better than ``other``: calmer or newly within the overshoot, else faster
        to settle by more than :data:`SETTLE_NOISE` (a tie keeps ``other``)."""
        mine, theirs = self.score(), other.score()
        if mine[:2] != theirs[:2]:
            return mine[:2] < theirs[:2]
        if self.settling_s is None:
            return False
        if other.settling_s is None:
            return True
        return self.settling_s < other.settling_s * (1.0 - SETTLE_NOISE)

    def as_dict(self) -> dict[str, object]:
        return {"gains": self.gains, "overshoot_pct": self.overshoot_pct,
                "settling_s": self.settling_s, "rise_s": self.rise_s,
                "following_error": self.following_error, "vibration": self.vibration,
                "phase": self.phase}


@dataclass
class TuneResult:
    before: Trial
    after: Trial
    original: dict[str, int]
    tuned: dict[str, int]
    inertia_ratio: float | None
    amps_per_accel: float | None
    trials: int
    writes: int
    source: str
    rate_hz: float
    limits_found: dict[str, int] = field(default_factory=dict)
    saved: bool = False
    persistence: str = ""
    save_hint: str = ""
    goal: str = "settling"

    def as_dict(self) -> dict[str, object]:
        return {"before": self.before.as_dict(), "after": self.after.as_dict(),
                "goal": self.goal,
                "original": self.original, "tuned": self.tuned,
                "inertia_ratio": self.inertia_ratio, "amps_per_accel": self.amps_per_accel,
                "trials": self.trials, "writes": self.writes, "source": self.source,
                "rate_hz": self.rate_hz, "vibration_limits": self.limits_found,
                "saved": self.saved, "persistence": self.persistence,
                "save_hint": self.save_hint}


def candidates(gain: TuningGain, start: int, minimum: int, maximum: int) -> list[int]:
    """Values from ``start`` up to the top of the range (down, for an inverse gain), each
    :data:`RAISE` times stronger than the last, the range's end last."""
    out: list[int] = []
    v = float(start)
    while len(out) < EEPROM_WRITES_PER_GAIN - 2:
        v = v / RAISE if gain.inverse else v * RAISE
        value = max(minimum, min(maximum, round(v)))
        if gain.keep_units_digit:
            value = keep_units(value, start, minimum, maximum)
        if value != start and (not out or value != out[-1]):
            out.append(value)
        if (v <= minimum) if gain.inverse else (v >= maximum):
            break
    return out


def keep_units(value: int, like: int, minimum: int, maximum: int) -> int:
    """``value`` with the units digit of ``like`` (a configuration bit), in range."""
    v = value - value % 10 + like % 10
    while v > maximum:
        v -= 10
    while v < minimum:
        v += 10
    return v


def inertia_ratio(record: Record, rotor_amps_per_accel: float | None,
                  counts_per_rev: int) -> tuple[float | None, float | None]:
    """(load / rotor inertia, A per rev/s^2) from a move's acceleration: the current over
    the speed's slope while the speed rises to its peak. None where it cannot be told."""
    if record.current is None or len(record.times) < 8:
        return None, None
    t, p = record.times, record.position
    speed = [(p[i + 1] - p[i]) / (t[i + 1] - t[i]) for i in range(len(p) - 1)]
    sign = 1.0 if record.target >= record.start else -1.0
    peak = max(range(len(speed)), key=lambda i: sign * speed[i])
    if peak < 4:
        return None, None
    n = peak
    ts = t[:n]
    mt, ms = sum(ts) / n, sum(speed[:n]) / n
    var = sum((x - mt) ** 2 for x in ts)
    if var <= 0:
        return None, None
    slope = sum((x - mt) * (y - ms) for x, y in zip(ts, speed[:n], strict=True)) / var
    amps = sum(record.current[:n]) / n
    if slope * sign <= 0:
        return None, None
    per_accel = abs(amps) / (abs(slope) / counts_per_rev)
    if rotor_amps_per_accel is None:
        return None, per_accel
    return max(0.0, per_accel / rotor_amps_per_accel - 1.0), per_accel


def alike(a: Trial, b: Trial) -> bool:
    """Two moves at the same gains that tell the same: neither clearly better, the same
    overshoot within :data:`LEARN_OVERSHOOT_PP`."""
    return (not a.improves_on(b) and not b.improves_on(a)
            and abs(a.overshoot_pct - b.overshoot_pct) <= LEARN_OVERSHOOT_PP)


def pick(tried: list[tuple[int, Trial]], start: int) -> tuple[int, Trial]:
    """The best of a search's ``tried`` values; of those tied with it (within
    :data:`SETTLE_NOISE`), the one nearest ``start``: a gain moves only as far as helps."""
    best = min(tried, key=lambda vt: vt[1].score())[1]
    tied = [vt for vt in tried if not best.improves_on(vt[1])]
    return min(tied, key=lambda vt: abs(math.log(max(vt[0], 1) / max(start, 1))))


class Tuner:
    """One tuning run on ``plant`` within ``limits``; ``on_trial`` sees every test move."""

    def __init__(self, plant: Plant, limits: Limits, counts_per_rev: int,
                 on_trial: Callable[[Trial], None] | None = None, *,
                 save: bool = False, goal: str = "settling",
                 on_kept: Callable[[dict[str, int]], None] | None = None) -> None:
        if limits.distance == 0:
            raise ServobusError("the test distance must not be zero")
        if goal not in GOALS:
            raise ServobusError(f"goal {goal!r}: one of {', '.join(GOALS)}")
        self.goal = goal
        self.plant = plant
        self.limits = limits
        self.counts_per_rev = counts_per_rev
        self.on_trial = on_trial
        #: Sees the kept gains before the first gain write (servobus.tune.kept records them
        #: for a run whose process is killed); what it raises ends the run, nothing written.
        self.on_kept = on_kept
        self.save = save
        if save and plant.profile.persistence is not Persistence.RAM_SAVE_COMMAND:
            raise ServobusError("these gains are not saved with a command: "
                                + plant.profile.save_hint)
        self.original: dict[str, int] = {}
        self.written: dict[str, int] = {}  # what the drive holds now
        self.writes = 0
        self.per_gain: dict[str, int] = {}
        self.trials = 0
        #: Where the run is: before, calm, soften, search <gain>, refine, verify (progress shown).
        self.phase = "before"
        self.origin: int | None = None
        self.outward = False
        eeprom = plant.profile.persistence is Persistence.EEPROM_EACH_WRITE
        self.budget = EEPROM_WRITE_BUDGET if eeprom else None
        self.margin = MARGIN if plant.source == "trace" else POLL_MARGIN

    # -------------------------------------------------------------- writes
    async def _write(self, name: str, value: int) -> bool:
        """Write ``name`` if it changes; False when the write budget is spent (not written)."""
        if self.written.get(name) == value:
            return True
        if not self._can_write(name, 1):
            return False
        self.plant.param_info(name).check(value)
        await self.plant.write_gain(name, value)
        self.written[name] = value
        self.writes += 1
        self.per_gain[name] = self.per_gain.get(name, 0) + 1
        return True

    def _can_write_all(self, names: list[str], count: int) -> bool:
        """Whether ``count`` more writes of each of ``names`` fit, the revert kept."""
        reserve = sum(1 for g, v in self.original.items()
                      if g in names or self.written.get(g) != v)
        return self.budget is None or (
            self.writes + count * len(names) + reserve <= self.budget
            and all(self.per_gain.get(n, 0) + count + 1 <= EEPROM_WRITES_PER_GAIN
                    for n in names))

    def _can_write(self, name: str, count: int) -> bool:
        """Whether ``count`` more writes of ``name`` fit the write budget, the revert kept."""
        # the revert of every gain that differs, and of ``name``, which may differ after
        reserve = sum(1 for g, v in self.original.items()
                      if g == name or self.written.get(g) != v)
        return self.budget is None or (
            self.writes + count + reserve <= self.budget
            and self.per_gain.get(name, 0) + count + 1 <= EEPROM_WRITES_PER_GAIN)

    async def revert(self) -> None:
        """The kept gains back, each only where it changed."""
        for name, value in self.original.items():
            if self.written.get(name) != value:
                await self.plant.write_gain(name, value)
                self.written[name] = value
                self.writes += 1

    # -------------------------------------------------------------- moves
    async def _move(self) -> Record:
        """To the far end of the distance, then back to the start, and so on."""
        await self.plant.settle(SETTLE_TIMEOUT_S)
        here = await self.plant.position()
        if self.origin is None:
            self.origin = here
        self.outward = not self.outward
        end = self.origin + self.limits.distance if self.outward else self.origin
        soft = self.limits.soft_limits
        if soft is not None and not soft[0] <= end <= soft[1]:
            raise TuneAborted(f"a test move to {self.limits.at(end)} would leave the soft "
                              f"limits {self.limits.at(*soft)}; nothing was moved")
        if abs(end - here) > 2 * abs(self.limits.distance):
            span = self.limits.at(self.origin, self.origin + self.limits.distance)
            raise TuneAborted(f"the motor stands at {self.limits.at(here)}, beyond the test "
                              f"span {span}")
        return await self.plant.test_move(end, self.limits.record_s)

    async def _trial(self) -> tuple[Trial, Record]:
        record = await self._move()
        self.trials += 1
        m = record.metrics()
        trial = Trial(dict(self.written), m.overshoot_pct, m.settling_time_s, m.rise_time_s,
                      m.following_error_max, vibration(record), self.phase)
        if self.on_trial is not None:
            self.on_trial(trial)
        if record.alarm_code:
            raise TuneAborted(f"the drive raised alarm {record.alarm_code} "
                              f"({record.alarm_text or 'alarm'})")
        if trial.vibration > self.limits.vibration_limit:
            raise TuneAborted(f"vibration {trial.vibration:.2f} beyond the limit "
                              f"{self.limits.vibration_limit:g}")
        return trial, record

    # -------------------------------------------------------------- the procedure
    async def run(self) -> TuneResult:
        plant = self.plant
        for g in plant.profile.gains:
            self.original[g.name] = await plant.read_gain(g.name)
        self.written = dict(self.original)
        if self.on_kept is not None:
            self.on_kept(dict(self.original))
        try:
            before, record = await self._trial()
            ratio, per_accel = inertia_ratio(record, plant.rotor_amps_per_accel(),
                                             self.counts_per_rev)
            found: dict[str, int] = {}
            self.phase = "calm"
            best = await self._calm(before, ratio)
            learnt = False
            for role in ORDER:
                if not learnt and not best.vibrates:  # learning moves only at calm gains
                    best, learnt = await self._learn(best), True
                    if self.goal == "settling" and plant.profile.learns_load:
                        self.phase = "soften"
                        best = await self._soften(best)
                gain = plant.profile.gain(role)
                if gain is not None:
                    self.phase = f"search {gain.name}"
                    best = await self._search(gain, best, found)
            if plant.source == "trace":  # polls time a step too coarsely for half steps
                self.phase = "refine"
                best = await self._refine(best)
            # the verify starts at rest, not in the wake of the search's last vibrating move
            self.phase = "verify"
            await plant.settle(VERIFY_SETTLE_S)
            after, _ = await self._trial()
            if after.vibrates:  # the verify shakes where the search did not: one step down
                for role in (GainRole.INTEGRAL, GainRole.POSITION):
                    gain = plant.profile.gain(role)
                    if gain is not None:
                        after = await self._lower_until_calm(gain, after)
            if self.save:
                await plant.save()
        except BaseException:
            await self._abort()
            raise
        return TuneResult(before, after, dict(self.original), dict(self.written), ratio,
                          per_accel, self.trials, self.writes, plant.source, plant.rate_hz,
                          found, saved=self.save,
                          persistence=plant.profile.persistence.value,
                          save_hint=plant.profile.save_hint, goal=self.goal)

    async def _abort(self) -> None:
        """Stop, then the kept gains back; a failed write back is said, not hidden."""
        try:
            await self.plant.stop()
        finally:
            try:
                await self.revert()
            except ServobusError as exc:
                raise TuneAborted(f"the kept gains could not be written back ({exc}); "
                                  f"they were {self.original}") from exc

    async def _calm(self, before: Trial, ratio: float | None) -> Trial:
        """Where the kept gains vibrate already (a load heavier than they suit: 5.2 "heavier
        loads ... bigger value of Speed Gain"): the speed gain scaled by the inertia found,
        then the position gain lowered step by step, until a move is calm."""
        trial = before
        speed = self.plant.profile.gain(GainRole.SPEED)
        if trial.vibrates and speed is not None and ratio:
            info = self.plant.param_info(speed.name)
            start = self.written[speed.name]
            scale = math.sqrt(1.0 + ratio)
            value = round(start / scale if speed.inverse else start * scale)
            value = max(info.minimum, min(info.maximum, value))
            if speed.keep_units_digit:
                value = keep_units(value, start, info.minimum, info.maximum)
            if value != start and await self._write(speed.name, value):
                trial, _ = await self._trial()
        # 5.2: "Decrease Integration Gain if load inertia is big and system oscillates",
        # then a softer position loop
        for role in (GainRole.INTEGRAL, GainRole.POSITION):
            gain = self.plant.profile.gain(role)
            if gain is not None:
                trial = await self._lower_until_calm(gain, trial)
        return trial

    async def _learn(self, trial: Trial) -> Trial:
        """Test moves at the gains held until the drive's response stops changing: a drive
        that adapts to its load (DMM Adaptive Tuning, 5.2) moves differently while it learns,
        and gains compared across that would be compared on different machines."""
        recent = [trial]
        for _ in range(LEARN_MOVES):
            if len(recent) >= LEARN_AGREE and all(
                    alike(recent[-1], t) for t in recent[-LEARN_AGREE:-1]):
                break
            trial, _ = await self._trial()
            recent.append(trial)
        return trial

    async def _soften(self, best: Trial) -> Trial:
        """The whole loop softer, position, speed and integral gains together (module doc,
        2): where the drive feeds forward the load it learnt, the feedback's part in a move
        is its correction, and a stiff loop's correction of a move the feed-forward already
        carries is overshoot (measured: DMM direct load at 30, 29/127/20 overshoots 5 % and
        settles in 72 ms, 4/16/3 overshoots 1.3 % and settles in 50). Scaled together the
        cascade keeps its order (position loop below the speed loop, the integral's zero
        below both); one gain at a time leaves it (Main 29 at Speed 40 shakes).

        A softer step counts only where it overshoots no more than the loop it started from:
        that is the sign that the feed-forward, not the feedback, carries the move. Where
        softening adds overshoot the feedback is still stopping the load, and a faster
        settling there was measured against gains not yet searched (DMM belt at 3: the
        defaults 40/40/20 settle in 119 ms at 2.8 %, 10/10/5 in 86 ms at 5.6 %; the searches
        from there ended at 71 ms, from 40/40/20 at 49)."""
        # the soft loop leans on a learnt feed-forward, and the learning moves' agreement at
        # stiff gains hides its last per cent (measured, direct load at 30: agreed at move 10,
        # 112 ms at 40/127/20; 5/17/3 then settled in 232 ms, on move 35 in 50 ms)
        for _ in range(LEARN_MOVES - self.trials):
            best, _ = await self._trial()
        gains = [g for r in SOFTEN_ROLES if (g := self.plant.profile.gain(r)) is not None]
        start = {g.name: self.written[g.name] for g in gains}
        tried: list[tuple[dict[str, int], Trial]] = [(start, best)]
        for k in range(1, SOFTEN_STEPS + 1):
            values = {g.name: self._scaled(g, start[g.name], SOFTEN ** k) for g in gains}
            changed = [n for n, v in values.items() if v != self.written[n]]
            # room for the step and, should it not be kept, the write back
            if not changed or not self._can_write_all(changed, 2):
                break
            for name in changed:
                await self._write(name, values[name])
            trial, _ = await self._trial()
            if trial.vibration >= ONSET or trial.overshoot_pct > MAX_OVERSHOOT_PCT:
                break  # softer still would be further from a calm, bounded move
            if trial.overshoot_pct <= best.overshoot_pct:
                tried.append((values, trial))
        fastest = min(tried, key=lambda vt: vt[1].score())[1]
        keep, chosen = next(vt for vt in tried if not fastest.improves_on(vt[1]))
        for name, value in keep.items():
            if not await self._write(name, value):  # not expected: the writes were kept
                raise TuneAborted(f"the write budget left no write to keep {name}={value}")
        return chosen

    def _scaled(self, gain: TuningGain, start: int, factor: float) -> int:
        """``start`` ``factor`` times softer, within the range (units digit kept)."""
        info = self.plant.param_info(gain.name)
        value = round(start * factor if gain.inverse else start / factor)
        value = max(info.minimum, min(info.maximum, value))
        if gain.keep_units_digit:
            value = keep_units(value, start, info.minimum, info.maximum)
        return value

    async def _lower_until_calm(self, gain: TuningGain, trial: Trial) -> Trial:
        info = self.plant.param_info(gain.name)
        for _ in range(CALM_STEPS):
            if not trial.vibrates:
                break
            start = self.written[gain.name]
            value = round(start * RAISE if gain.inverse else start / RAISE)
            value = max(info.minimum, min(info.maximum, value))
            if gain.keep_units_digit:
                value = keep_units(value, start, info.minimum, info.maximum)
            if value == start or not await self._write(gain.name, value):
                break
            trial, _ = await self._trial()
        return trial

    def _step(self, gain: TuningGain, harder: bool, factor: float) -> int | None:
        """``gain`` one step of ``factor`` harder or softer; None at the range's end."""
        info = self.plant.param_info(gain.name)
        start = self.written[gain.name]
        up = harder != gain.inverse  # a larger register value
        value = round(start * factor if up else start / factor)
        value = max(info.minimum, min(info.maximum, value))
        if gain.keep_units_digit:
            value = keep_units(value, start, info.minimum, info.maximum)
        return None if value == start else value

    async def _refine(self, best: Trial) -> Trial:
        """Fine tuning (module doc, 3): a step each way per gain, kept while it helps."""
        for factor in FINE:
            best = await self._refine_by(best, factor)
        return best

    async def _refine_by(self, best: Trial, factor: float) -> Trial:
        for role in ORDER:
            gain = self.plant.profile.gain(role)
            if gain is None:
                continue
            for harder in (True, False):
                moved = False
                for _ in range(CALM_STEPS):
                    kept = self.written[gain.name]
                    value = self._step(gain, harder, factor)
                    # a step and, should it not help, the step back: both or neither
                    if value is None or not self._can_write(gain.name, 2):
                        break
                    await self._write(gain.name, value)
                    trial, _ = await self._trial()
                    if trial.vibration >= ONSET or not trial.improves_on(best):
                        await self._write(gain.name, kept)
                        break
                    best, moved = trial, True
                if moved:
                    break  # improved this way: the other way undoes it
        return best

    async def _search(self, gain: TuningGain, best: Trial, found: dict[str, int]) -> Trial:
        """Raise ``gain`` until a move vibrates, back off, keep the best (module doc)."""
        info = self.plant.param_info(gain.name)
        start = self.written[gain.name]
        tried: list[tuple[int, Trial]] = [(start, best)]
        limit: int | None = None
        for value in candidates(gain, start, info.minimum, info.maximum):
            # room for this value, the write back to calm and the value kept at the end
            if not self._can_write(gain.name, 3) or not await self._write(gain.name, value):
                break  # the write budget is spent: keep what was found so far
            trial, _ = await self._trial()
            if trial.vibration >= ONSET:
                limit = value
                await self._write(gain.name, tried[-1][0])  # calm again before anything else
                break
            tried.append((value, trial))
        if limit is not None:
            found[gain.name] = limit
            if gain.inverse:
                tried = [(v, t) for v, t in tried if v == start or v * self.margin >= limit]
            else:
                tried = [(v, t) for v, t in tried if v == start or v <= limit * self.margin]
        value, chosen = pick(tried, start)
        if chosen.vibrates or chosen.overshoot_pct > MAX_OVERSHOOT_PCT or value == start:
            # raising did not help: the other way (5.2: a lower Integration Gain on a big
            # inertia; a softer position loop on a compliant load; YZ-AIM belt at 30: Ti
            # 77 -> 296 ms, settling 244 -> 140 ms)
            down = candidates(TuningGain(gain.role, gain.name, not gain.inverse,
                                         gain.keep_units_digit), start, info.minimum,
                              info.maximum)[:CALM_STEPS]
            calm_start = not chosen.vibrates
            for lower in down:
                if not self._can_write(gain.name, 2) or not await self._write(gain.name, lower):
                    break
                trial, _ = await self._trial()
                tried.append((lower, trial))
                if calm_start and trial.vibration >= ONSET:
                    break  # from calm gains, the first shaking step ends the way down too
            value, chosen = pick(tried, start)
        if not await self._write(gain.name, value):  # not expected: the writes were kept
            raise TuneAborted(f"the write budget left no write to keep {gain.name}={value}")
        return chosen
