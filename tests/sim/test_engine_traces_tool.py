"""tools/engine_traces: its digest follows every bit of the engine's traces."""

from __future__ import annotations

from pathlib import Path

from servobus.sim.core import engine
from tools.engine_traces import case_digest, engine_module

SLIDING = "return wn if (wn > 0.0) == (w > 0.0) else 0.0"


def test_the_same_engine_gives_the_same_digest_and_a_changed_one_another(
        tmp_path: Path) -> None:
    source = Path(engine.__file__).read_text()
    assert source.count(SLIDING) == 1
    changed = tmp_path / "engine_changed.py"  # only the sign of a stopped speed's zero
    changed.write_text(source.replace(SLIDING, SLIDING.replace("else 0.0", "else -0.0")))
    copy = tmp_path / "engine_copy.py"
    copy.write_text(source)
    now = case_digest(engine, "belt", 0.05, 0.0)
    assert case_digest(engine_module(str(copy)), "belt", 0.05, 0.0) == now
    assert case_digest(engine_module(str(changed)), "belt", 0.05, 0.0) != now
