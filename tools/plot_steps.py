"""Step responses of a virtual DMM drive on a chosen load, as a table or a plot (docs/tuning.md).

``python -m tools.plot_steps`` prints the step metrics of the drive's own move (what the GUI's
step test commands: a quarter turn on the Max Speed / Max Accel profile) at three Main Gains
on a belt at inertia ratio 10 - the table in docs/tuning.md. ``--plot FILE.png`` also draws
motor and load positions and the current (needs matplotlib; plots are not committed).
``--load``, ``--inertia``, ``--resonance``, ``--load-torque``, ``--main``, ``--speed``,
``--integ``, ``--trq``, ``--accel``, ``--raw`` (a reference jump instead of the profile move)
choose another case. Everything runs on simulated time: the same arguments give the same
figures on any machine.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from servobus.axis.step_metrics import StepMetrics, step_metrics
from servobus.families.dmm import units as U
from servobus.sim.core.loads import PRESETS, load_settings
from servobus.sim.core.motor import Motor
from servobus.sim.core.steps import StepTrace, record
from servobus.sim.dmm.drive import VirtualDrive

STEP_COUNTS = U.COUNTS_PER_REV // 4
COMMAND_UNITS_PER_COUNT = 1 / 4  # move_relative at the factory GEAR_NUM 4096


def run_step(main: int, *, speed: int, integ: int, trq: int, accel: int, raw: bool,
             load: dict[str, object], seconds: float) -> StepTrace:
    if raw:  # the protocol-free core: the reference jumps, no profile, no feed-forward
        core = Motor(U.MODELS[U.DEFAULT_MODEL])
        core.set_gains(main, speed, integ, trq, 127)
        core.set_mechanics(load_settings(load))
        return record(core, lambda: core.follow_counts(STEP_COUNTS, 0.0), seconds)
    drive = VirtualDrive(1)
    drive.set_mechanics(load_settings(load))
    for name, value in (("main_gain", main), ("speed_gain", speed), ("int_gain", integ),
                        ("trq_cons", trq), ("max_accel", accel)):
        drive.set_param(name, value)
    return record(drive, lambda: drive.move_relative(round(STEP_COUNTS
                                                           * COMMAND_UNITS_PER_COUNT)),
                  seconds)


def figures(trace: StepTrace, *, load_side: bool = False) -> StepMetrics:
    positions = trace.load_position if load_side else trace.position
    return step_metrics([0.0, *trace.times], [0.0, *positions], 0.0, 0.0, STEP_COUNTS,
                        position_errors=[0.0, *trace.error])


def _ms(seconds: float | None) -> str:
    return "-" if seconds is None else f"{seconds * 1000:.1f}"


def table(rows: Sequence[tuple[int, StepTrace]]) -> str:
    """A Markdown table of motor and load figures per Main Gain."""
    lines = ["| Main Gain | rise (ms) | overshoot (%) | settling (ms) | max following error "
             "(counts) | load overshoot (%) | load settling (ms) | peak current (A) |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for main, trace in rows:
        m, ld = figures(trace), figures(trace, load_side=True)
        peak = max(abs(c) for c in trace.current)
        lines.append(f"| {main} | {_ms(m.rise_time_s)} | {m.overshoot_pct:.1f} | "
                     f"{_ms(m.settling_time_s)} | {m.following_error_max or 0:.0f} | "
                     f"{ld.overshoot_pct:.1f} | {_ms(ld.settling_time_s)} | {peak:.1f} |")
    return "\n".join(lines)


def plot(rows: Sequence[tuple[int, StepTrace]], path: str) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise SystemExit("--plot needs matplotlib (pip install matplotlib)") from None
    fig, (ax_pos, ax_cur) = plt.subplots(2, 1, sharex=True, figsize=(9, 7))
    for main, trace in rows:
        ms = [t * 1000 for t in trace.times]
        line, = ax_pos.plot(ms, trace.position, label=f"Main Gain {main}: motor")
        ax_pos.plot(ms, trace.load_position, linestyle="--", color=line.get_color(),
                    label=f"Main Gain {main}: load")
        ax_cur.plot(ms, trace.current, color=line.get_color(), label=f"Main Gain {main}")
    ax_pos.axhline(STEP_COUNTS, color="grey", linewidth=0.5)
    ax_pos.set_ylabel("position (counts)")
    ax_cur.set_ylabel("current (A)")
    ax_cur.set_xlabel("time since the command (ms)")
    ax_pos.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path)


def parse(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line; its defaults are the docs/tuning.md table's case."""
    parser = argparse.ArgumentParser(prog="python -m tools.plot_steps",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--load", choices=tuple(PRESETS), default="belt")
    parser.add_argument("--inertia", type=float, default=10.0)
    parser.add_argument("--resonance", type=float)
    parser.add_argument("--load-torque", type=float)
    parser.add_argument("--main", type=int, nargs="+", default=[10, 40, 80])
    parser.add_argument("--speed", type=int, default=80)
    parser.add_argument("--integ", type=int, default=5)
    parser.add_argument("--trq", type=int, default=127)
    parser.add_argument("--accel", type=int, default=10, help="Max Accel")
    parser.add_argument("--raw", action="store_true",
                        help="a reference jump on the protocol-free core instead of the move")
    parser.add_argument("--seconds", type=float, default=0.8)
    parser.add_argument("--plot", metavar="FILE.png")
    return parser.parse_args(argv)


def runs(args: argparse.Namespace) -> list[tuple[int, StepTrace]]:
    """One step per Main Gain of ``args``."""
    load = {"load": args.load, "inertia": args.inertia, "resonance": args.resonance,
            "load_torque": args.load_torque}
    return [(g, run_step(g, speed=args.speed, integ=args.integ, trq=args.trq,
                         accel=args.accel, raw=args.raw, load=load, seconds=args.seconds))
            for g in args.main]


def main(argv: Sequence[str] | None = None) -> int:
    args = parse(argv)
    rows = runs(args)
    print(table(rows))
    if args.plot:
        plot(rows, args.plot)
        print(f"plot written to {args.plot}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
