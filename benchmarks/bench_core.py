"""Drive core speed: stepped time vs real time, and 16 drives in real time on one core.

Targets (issue 3): one drive in stepped time >= 20x real time; 16 drives in real time at
the control rate using <= 50 % of one core. All drives keep moving (no quiescent shortcut)
except in the explicitly idle case.
"""

from __future__ import annotations

import time

from benchmarks.verdict import mark, percent, summary
from servobus.sim.core.loads import load_settings
from servobus.sim.dmm.drive import CONTROL_HZ, VirtualDrive

TICK_S = 0.001  # how often a server calls advance_to() (a front end's event-loop tick)


def busy_drive(drive_id: int, phase: int = 0) -> VirtualDrive:
    """Half the drives turn at a constant speed on a rigid load; the other half move on a
    belt (two masses: the dearer path of the model, docs/tuning.md)."""
    d = VirtualDrive(drive_id)
    d.set_load(inertia=2e-4, friction=0.05)
    if phase % 2 == 0:
        d.set_mechanics(load_settings({"load": "belt"}))
    if phase % 2:
        d.turn_const_speed(1500 - 100 * phase)
    else:
        d.move_relative(10_000_000)  # several seconds of S-curve travel
    return d


def keep_busy(d: VirtualDrive, k: int) -> None:
    """Every simulated 0.25 s: a new DTPU target, so nothing ever settles."""
    d.move_relative(200_000 if k % 2 else -150_000)


def stepped(seconds: float, tick: float) -> float:
    d = busy_drive(1)
    c0 = time.process_time()
    t, k = 0.0, 0
    while t < seconds:
        t += tick
        d.advance_to(t)
        if t >= 0.25 * (k + 1):
            k += 1
            keep_busy(d, k)
    cpu = time.process_time() - c0
    assert d.alarm == 0, d.alarm
    return seconds / cpu


def realtime(n: int, seconds: float, idle: bool = False) -> tuple[float, float]:
    """(CPU fraction of one core, worst lag behind wall clock in s)."""
    drives = [VirtualDrive(i + 1) if idle else busy_drive(i + 1, i) for i in range(n)]
    c0, w0 = time.process_time(), time.perf_counter()
    k, lag = 0, 0.0
    nxt = w0
    while True:
        now = time.perf_counter() - w0
        if now >= seconds:
            break
        for d in drives:
            d.advance_to(now)
        if not idle and now >= 0.25 * (k + 1):
            k += 1
            for d in drives:
                keep_busy(d, k)
        lag = max(lag, time.perf_counter() - w0 - now)
        nxt += TICK_S
        delay = nxt - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    cpu = (time.process_time() - c0) / (time.perf_counter() - w0)
    assert all(d.alarm == 0 for d in drives)
    return cpu, lag


def main() -> None:
    print(f"drive core @ {CONTROL_HZ} Hz control rate (pure Python)")
    r_tick = stepped(20.0, TICK_S)
    r_bulk = stepped(20.0, 0.25)
    verdict = mark("core: 1 drive stepped time", r_tick, at_least=20, show="{:g}x".format)
    print(f"  1 drive, stepped time, advance every {TICK_S * 1000:g} ms: {r_tick:6.1f}x real time"
          f"  {verdict}")
    print(f"  1 drive, stepped time, advance every 250 ms:  {r_bulk:6.1f}x real time")
    cpu, lag = realtime(16, 3.0)
    verdict = mark("core: 16 drives real time CPU", cpu, at_most=0.5, show=percent)
    print(f"  16 moving drives (8 on a belt), real time, {TICK_S * 1000:g} ms ticks: CPU "
          f"{cpu * 100:5.1f} % of one core {verdict}; worst lag {lag * 1000:.2f} ms")
    cpu_idle, _ = realtime(16, 1.0, idle=True)
    print(f"  16 idle drives (settled fast path): CPU {cpu_idle * 100:5.1f} % of one core")


if __name__ == "__main__":
    main()
    print(summary())
