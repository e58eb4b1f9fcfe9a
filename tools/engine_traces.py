"""A digest of the servo engine's traces, to show a hot-loop change keeps them bit-identical.

``python -m tools.engine_traces`` runs :class:`servobus.sim.core.engine.ServoEngine` period
by period through every servo mode (position moves, a wave, free coasting, speed servo,
torque servo with and without a speed limit, a blocked shaft) on each load preset (screw,
direct, belt) at four frictions and load torques, hashes every state variable after every
period, and prints one digest per case and one for all. ``--engine FILE`` runs a copy of
the engine module instead (``git show main:servobus/sim/core/engine.py > /tmp/old.py``):
the same digests mean the same traces, to the bit. Simulated time only: the same engine
gives the same digests on any machine.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import struct
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Any

from servobus.families.dmm import units as U
from servobus.sim.core.loads import PRESETS

FIELDS = ("p", "w", "pl", "wl", "tq", "tq_cmd", "integ", "heat", "ref", "w_est")
FRICTIONS = ((0.0, 0.0), (0.05, 0.0), (0.2, 0.4), (0.02, -0.1))  # N m: Coulomb, load torque


def engine_module(path: str | None) -> ModuleType:
    if path is None:
        from servobus.sim.core import engine
        return engine
    spec = importlib.util.spec_from_file_location("engine_under_test", path)
    if spec is None or spec.loader is None:
        raise SystemExit(f"error: cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def case_digest(engine: ModuleType, preset: str, friction: float, load_torque: float) -> str:
    model = U.MODELS["DYN2-TL"]
    e: Any = engine.ServoEngine(model)
    p = PRESETS[preset]
    e.load_inertia = p.inertia * model.rotor_inertia_kgm2
    e.resonance_hz, e.damping = p.resonance, p.damping
    e.load_friction, e.load_torque = friction, load_torque
    e.set_loop(*e.loop)
    e.set_profile(U.rpm_to_counts_per_s(3000), U.rpm_to_counts_per_s(3000) * 20)
    h = hashlib.sha256()

    def run(periods: int, chunk: int = 1) -> None:
        for _ in range(periods // chunk):
            e.run(chunk)
            for f in FIELDS:
                h.update(struct.pack("<d", float(getattr(e, f))))
            h.update(struct.pack("<qq", e.steps, int(e.trip_code)))

    e.go_to(200_000.0, 0.002)
    run(2000)
    e.go_to(-50_000.0, 0.0)
    run(3000, 7)
    e.run_speed(-300_000.0, 0.001)
    run(1000)
    e.start_wave(False, 3000.0, 20.0, None)
    run(800)
    e.stop_wave(0.0)
    run(1500, 3)
    e.disturbance = 0.3
    e.wake()
    run(800)
    e.servo = engine.Servo.FREE  # coasting from speed, then pushed
    e.w = 400_000.0
    e.wl = e.w if e.rigid else 390_000.0
    e.wake()
    run(3000)
    e.disturbance = 2.0
    e.wake()
    run(500)
    e.disturbance = 0.0
    e.servo = engine.Servo.SPEED
    e.set_soft_start(0.05)
    e.hold_here()
    e.speed_target = 200_000.0
    e.wake()
    run(2000)
    e.speed_target = -100_000.0
    e.wake()
    run(1000, 5)
    e.servo = engine.Servo.TORQUE
    e.speed_target = 1.5
    e.wake()
    run(1000)
    e.torque_speed_limit, e.speed_target = 150_000.0, -2.0
    e.wake()
    run(1500)
    e.speed_target = 0.1
    e.wake()
    run(500)
    e.blocked = True
    e.wake()
    run(200)
    return h.hexdigest()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--engine", help="a copy of servobus/sim/core/engine.py to run instead")
    parser.add_argument("--preset", choices=sorted(PRESETS), action="append",
                        help="only these presets [default: all]")
    args = parser.parse_args(argv)
    engine = engine_module(args.engine)
    total = hashlib.sha256()
    for preset in args.preset or PRESETS:
        for friction, load_torque in FRICTIONS:
            digest = case_digest(engine, preset, friction, load_torque)
            total.update(bytes.fromhex(digest))
            print(f"{preset:6} friction {friction:<4g} load torque {load_torque:<4g} "
                  f"{digest[:16]}")
    print(f"all {total.hexdigest()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
