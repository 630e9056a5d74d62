"""benchmarks/statistics_cost.py: times ermrl's statistics against rliable's own, after checking they are equal."""

from pathlib import Path

from cli_runs import script

SCRIPT = Path(__file__).resolve().parent.parent / "benchmarks" / "statistics_cost.py"


def _run(*args):
    return script(SCRIPT, *args)


def test_it_prints_both_medians_and_their_ratio():
    done = _run("--repeats", "1", "--reps", "50")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split(":")[0] for line in lines] == ["ermrl", "rliable's own statistics", "ratio"]
    assert "for the IQM CI and P(X > Y) CI of 10 seeds, 50 resamples" in lines[0]


def test_bad_counts_are_one_line_and_exit_code_2():
    for flag in ("--repeats", "--reps"):
        done = _run(flag, "0")
        assert done.returncode == 2 and done.stdout == ""
        assert done.stderr.strip().splitlines()[-1] == f"statistics_cost.py: error: {flag} must be at least 1, got 0"
