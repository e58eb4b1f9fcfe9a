"""servobus.tune on simulated time (servobus.sim.tune_plant): the procedure, its abort
paths (alarm, vibration, limit, Ctrl-C), the revert, the poll-only path, the write rules."""

from __future__ import annotations

import asyncio

import pytest

from servobus.axis.connect import connect_async
from servobus.axis.types import GainRole, TuningGain
from servobus.errors import ServobusError
from servobus.families.yzaim.family import YZAIM
from servobus.sim.core.loads import load_settings
from servobus.sim.tune_plant import SteppedPlant
from servobus.tune.axis_plant import AxisPlant
from servobus.tune.tuner import (
    EEPROM_WRITE_BUDGET,
    Limits,
    TuneAborted,
    Tuner,
    TuneResult,
    candidates,
    keep_units,
)


def dmm(load: str = "direct", inertia: float = 10, **kw: object) -> SteppedPlant:
    return SteppedPlant.dmm(load_settings({"load": load, "inertia": inertia}), **kw)


def tune(plant: SteppedPlant, **limits: object) -> TuneResult:
    cpr = plant.counts_per_rev
    return asyncio.run(Tuner(plant, Limits(limits.pop("distance", cpr // 4),  # type: ignore[arg-type]
                                           **limits), cpr).run())  # type: ignore[arg-type]


def gains_now(plant: SteppedPlant) -> dict[str, int]:
    return {g.name: asyncio.run(plant.read_gain(g.name)) for g in plant.profile.gains}


def test_a_heavy_direct_load_is_tuned_calm_and_within_the_overshoot() -> None:
    # Measured: inertia 10 at the defaults overshoots 20.3 % and rings (vibration 0.093);
    # tuned: Speed Gain 122, overshoot 0.2 %, settled in 51 ms, calm (0.000).
    plant = dmm()
    result = tune(plant)
    assert result.before.overshoot_pct > 15.0 and result.before.vibrates
    assert result.after.overshoot_pct <= 10.0 and not result.after.vibrates
    assert result.after.settling_s is not None and result.after.settling_s < 0.1
    assert result.inertia_ratio is not None and 6.0 < result.inertia_ratio < 12.0
    assert gains_now(plant) == result.tuned != result.original


def test_every_write_changes_the_gain_and_the_run_keeps_its_eeprom_budget() -> None:
    plant = dmm("screw", 0)
    result = tune(plant)
    assert result.writes == len(plant.gain_writes) <= EEPROM_WRITE_BUDGET
    held = gains_now(dmm("screw", 0))  # the defaults
    for name, value in plant.gain_writes:
        assert held[name] != value  # written only when it changes
        held[name] = value


def test_revert_on_request_writes_the_kept_gains_back() -> None:
    plant = dmm()
    tuner = Tuner(plant, Limits(plant.counts_per_rev // 4), plant.counts_per_rev)
    before = gains_now(plant)
    asyncio.run(tuner.run())
    assert gains_now(plant) != before
    asyncio.run(tuner.revert())
    assert gains_now(plant) == before


class AlarmingPlant(SteppedPlant):
    """Reports an alarm after the ``at``-th test move (what the drive's status would say)."""

    at = 3

    def alarm(self) -> tuple[int, str]:
        return (3, "over power") if self.moves >= self.at else super().alarm()


def test_an_alarm_aborts_stops_and_reverts() -> None:
    plant = AlarmingPlant(dmm().core)
    before = gains_now(plant)
    with pytest.raises(TuneAborted, match="alarm 3"):
        tune(plant)
    assert plant.moves == AlarmingPlant.at and plant.stops == 1
    assert gains_now(plant) == before


def test_vibration_beyond_the_limit_aborts_and_reverts() -> None:
    # Bare rotor: raising the Speed Gain buzzes at 110 (vibration ~0.7); the limit 0.2 stops it.
    plant = dmm("screw", 0)
    before = gains_now(plant)
    with pytest.raises(TuneAborted, match="vibration"):
        tune(plant, vibration_limit=0.2)
    assert plant.stops == 1 and gains_now(plant) == before


def test_a_move_beyond_the_soft_limits_is_refused_before_anything_moves() -> None:
    plant = dmm()
    here = asyncio.run(plant.position())
    with pytest.raises(TuneAborted, match="soft limits") as refused:
        tune(plant, soft_limits=(here - 100, here + 1000))
    assert plant.moves == 0 and plant.gain_writes == []
    assert f"limits {here - 100} .. {here + 1000} counts" in str(refused.value)
    # a machine axis's messages are in its unit (mm here: 1,000 counts a mm, reversed)
    with pytest.raises(TuneAborted, match=r"limits -1\.1 .. -0\.1 mm"):
        tune(plant, soft_limits=(100, 1100), to_user=lambda c: -c / 1000, unit="mm")


def test_ctrl_c_during_a_move_stops_and_reverts() -> None:
    plant = dmm()
    before = gains_now(plant)

    def interrupt(p: SteppedPlant, period: int) -> None:
        if p.moves == 4 and period == 100:
            raise KeyboardInterrupt

    plant.during_move.append(interrupt)
    with pytest.raises(KeyboardInterrupt):
        tune(plant)
    assert plant.stops == 1 and gains_now(plant) == before


def test_poll_only_sees_no_position_error_and_still_tunes_calm() -> None:
    # Trace off: 100 Hz samples of position and current. Measured: overshoot 0.0 %, calm.
    plant = dmm("direct", 10, trace=False)
    record = asyncio.run(plant.test_move(plant.counts_per_rev // 8, 0.3))  # from 0
    assert record.error is None and len(record.times) == 30
    result = tune(plant)
    assert result.source == "poll" and result.after.following_error is None
    assert not result.after.vibrates and result.after.overshoot_pct <= 10.0


@pytest.mark.slow  # some 50 test moves of a two-mass plant: 3 - 7 s of CPU
def test_a_yzaim_belt_at_10_is_tuned_as_fast_as_the_grid_finds() -> None:
    # Measured: position kp 740, speed kp 2,420, Ti 151 ms (the integral found softer than
    # the search's start), settling 95 ms, calm; the benchmark grid's best settles in 95 ms.
    plant = SteppedPlant.yzaim(load_settings({"load": "belt", "inertia": 10}))
    result = tune(plant)
    assert result.after.settling_s is not None and result.after.settling_s < 0.12
    assert not result.after.vibrates and result.after.overshoot_pct <= 10.0


@pytest.mark.slow  # some 60 test moves of a two-mass plant: 3 - 6 s of CPU
def test_a_yzaim_belt_at_30_gets_a_softer_integral_than_raising_finds() -> None:
    # Issue 35's miss: the integral search only raised from the calm phase's Ti 77 and the
    # run ended at 231 ms (the grid's best: 141 ms). Stepping softer where raising does not
    # help finds Ti 296 ms; measured: settling 140 ms, overshoot 1.2 %, calm.
    plant = SteppedPlant.yzaim(load_settings({"load": "belt", "inertia": 30}))
    result = tune(plant)
    assert result.tuned["speed_loop_integration_time"] > 150
    assert result.after.settling_s is not None and result.after.settling_s < 0.176
    assert not result.after.vibrates and result.after.overshoot_pct <= 10.0


def test_heavy_dmm_loads_end_within_the_overshoot() -> None:
    # Adaptive Tuning learns the load (docs/tuning.md): measured 1.5 % on the direct load at
    # inertia 30, 3.5 % on the belt at 30 (goal settling: the loop softened; 4.9 % and 7.5 %
    # before that step; no gain set stayed within 10 % under the old bound of 4 x the rotor).
    for load in ("direct", "belt"):
        result = tune(dmm(load, 30))
        assert result.after.overshoot_pct <= 10.0 and not result.after.vibrates, load


def test_yzaim_gains_keep_their_configuration_digit_and_save_only_when_asked() -> None:
    plant = SteppedPlant.yzaim(load_settings({"load": "direct", "inertia": 10}))
    asyncio.run(plant.write_gain("speed_loop_kp", 1001))  # pulse polarity bit set
    result = tune(plant)
    assert result.tuned["speed_loop_kp"] % 10 == 1
    assert result.tuned["position_loop_kp"] % 10 == 0
    assert plant.saved == 0


def test_candidates_rise_to_the_range_end_within_the_budget_per_gain() -> None:
    up = candidates(TuningGain(GainRole.SPEED, "speed_gain"), 40, 1, 127)
    assert up[0] == 56 and up[-1] == 127 and up == sorted(up)
    ti = YZAIM.param("speed_loop_integration_time")
    down = candidates(TuningGain(GainRole.INTEGRAL, ti.name, inverse=True), 20, ti.minimum,
                      ti.maximum)
    assert down == sorted(down, reverse=True) and down[-1] == ti.minimum
    assert keep_units(8064, 1001, 60, 10000) == 8061
    assert keep_units(30000, 1509, 60, 30000) == 29999


def test_save_only_where_the_family_saves_with_a_command() -> None:
    yz = SteppedPlant.yzaim(load_settings({"load": "direct", "inertia": 3}))
    cpr = yz.counts_per_rev
    result = asyncio.run(Tuner(yz, Limits(cpr // 4), cpr, save=True).run())
    assert result.saved and yz.saved == 1
    with pytest.raises(ServobusError, match="EEPROM"):  # DMM: written to EEPROM as made
        Tuner(dmm(), Limits(1000), 65536, save=True)


async def test_the_axis_plant_reads_the_trace_or_polls_on_a_sim_axis() -> None:
    # Wall clock, 0.3 s a move on a paced line (38,400 baud): the trace gives 4 kHz samples
    # with the position error, the poll path what the link reads (position and current).
    async with await connect_async("sim://dyn232?load=direct&inertia=3") as axis:
        traced = AxisPlant(axis)
        record = await traced.test_move(8192, 0.3)
        assert traced.source == "trace" and traced.rate_hz == 4000.0
        assert record.error is not None and abs(record.position[-1] - 8192) < 50
        polled = AxisPlant(axis, trace=False)
        record = await polled.test_move(0, 0.3)
        assert polled.source == "poll" and record.error is None
        assert 0 < polled.rate_hz < 1000.0 and abs(record.position[-1]) < 50  # paced line
