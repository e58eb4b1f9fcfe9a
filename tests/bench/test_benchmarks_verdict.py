"""The benchmarks mark each figure OK/MISS against its target and end with a summary line."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from benchmarks import verdict as V


@pytest.fixture(autouse=True)
def fresh() -> Iterator[None]:
    V.FIGURES.clear()
    V.ERRORS.clear()
    yield
    V.FIGURES.clear()
    V.ERRORS.clear()


def test_marks_and_summary() -> None:
    assert V.mark("polls", 0.936, at_least=0.97, show=V.percent) == "(target >= 97 %) MISS"
    assert V.mark("polls exact", 0.97, at_least=0.97, show=V.percent) == "(target >= 97 %) OK"
    assert V.mark("read", 0.0232, at_most=0.025,
                  show=lambda s: f"{s * 1e3:g} ms") == "(target <= 25 ms) OK"
    assert V.mark("cpu", 0.51, at_most=0.5, show=V.percent) == "(target <= 50 %) MISS"
    print(V.error("bench_x", RuntimeError("no port")))
    assert V.summary() == ("summary: 4 figure(s) with a target, 2 OK, 2 MISS (polls; cpu); "
                           "1 benchmark(s) could not run (bench_x)")


def test_mark_needs_exactly_one_bound() -> None:
    with pytest.raises(ValueError):
        V.mark("x", 1.0)
    with pytest.raises(ValueError):
        V.mark("x", 1.0, at_least=0, at_most=2)


def test_runner_reports_a_broken_benchmark_and_exits_0(monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    import pkgutil

    import benchmarks.__main__ as runner

    monkeypatch.setattr(pkgutil, "iter_modules",
                        lambda path: [type("M", (), {"name": "bench_missing_module"})()])
    assert runner.main([]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("bench_missing_module: ERROR ModuleNotFoundError")
    assert out[-1] == ("summary: 0 figure(s) with a target, 0 OK, 0 MISS; "
                       "1 benchmark(s) could not run (bench_missing_module)")


def test_runner_options_select_nothing(monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    """``faults --seconds 232``: the value 232 is the benchmark's, not a selector of
    bench_dyn232_*."""
    import pkgutil

    import benchmarks.__main__ as runner

    names = ["bench_dyn232_missing", "bench_faults_missing"]
    monkeypatch.setattr(pkgutil, "iter_modules",
                        lambda path: [type("M", (), {"name": n})() for n in names])
    assert runner.main(["faults", "--seconds", "232"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in out if "ERROR" in line] == ["bench_faults_missing"]
