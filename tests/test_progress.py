"""Progress when the output is not a terminal: whole lines (no control codes, nothing cut), at a steady pace, with an
ETA; checked on real `ermrl train` / `ermrl evolve` subprocesses with their output piped."""

import io
import math
import os
import re
import subprocess

from rich.console import Console

from ermrl.cli.progress import EvolutionBar, TrainingBar
from ermrl.evolution.evolve import GenerationProgress
from ermrl.training import Progress

from cli_runs import COMMAND

HMS = r"\d+:\d\d:\d\d"
TRAIN_LINE = re.compile(rf"(?P<label>.+): (?P<done>[\d,]+)k/(?P<total>[\d,]+)k steps \((?P<pct>\d+)%\) \| "
                        rf"(?P<rate>[\d,]+) agent-steps/s \| elapsed {HMS} \+ compile \d+ s \| ETA (?P<eta>{HMS})")
GEN_LINE = re.compile(rf"gen (?P<gen>\d+) \| (?P<completed>\d+)/(?P<trials>\d+) trials \| best (?P<best>.+?) \| "
                      rf"(training (?P<pct>\d+)% \| [\d,]+ agent-steps/s|generation done) \| study ETA (?P<eta>{HMS}|\?)")


def run(*args, cwd, merged=False):
    """The CLI with its output piped, stdout block-buffered as Python makes it by default for a pipe."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    return subprocess.run([*COMMAND, *args], cwd=cwd, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT if merged else subprocess.PIPE, text=True, timeout=900, env=env)


def assert_plain(text: str) -> None:
    assert "\x1b" not in text and "\r" not in text and "…" not in text, repr(text[-500:])
    assert text.endswith("\n")  # every line complete


def test_piped_train_prints_whole_progress_lines(tmp_path):
    r = run("train", "--env", "CartPole-v1", "--seeds", "2", "--timesteps", "8192", "--out", str(tmp_path / "t"),
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert_plain(r.stderr)
    lines = r.stderr.splitlines()
    assert lines[0] == "CartPole-v1 × 2 seeds: compiling"
    progress = [TRAIN_LINE.fullmatch(line) for line in lines[1:]]
    assert progress and all(progress), lines
    assert all(m["label"] == "CartPole-v1 × 2 seeds" and m["total"] == "16" for m in progress)
    assert [int(m["pct"]) for m in progress] == sorted(int(m["pct"]) for m in progress)
    assert progress[-1]["done"] == "16" and progress[-1]["pct"] == "100" and progress[-1]["eta"] == "0:00:00"


def test_piped_evolve_prints_one_line_per_generation_in_order_with_the_results(tmp_path):
    r = run("evolve", "--env", "CartPoleNoVel-v1", "--trials", "4", "--popsize", "2", "--sampler", "random",
            "--seeds", "1", "--timesteps", "2048", "--fixed-iss", "1.0", "--study", "piped", "--no-estimate",
            cwd=tmp_path, merged=True)
    assert r.returncode == 0, r.stdout
    assert_plain(r.stdout)
    lines = r.stdout.splitlines()
    assert lines[0].startswith("study 'piped' in sqlite:///runs/piped/study.db: 0/4 trials done")  # results stay first
    progress = [(i, GEN_LINE.fullmatch(line)) for i, line in enumerate(lines) if line.startswith("gen ")]
    assert all(m for _, m in progress), lines
    done = [m for _, m in progress if m["pct"] is None]
    assert [(m["gen"], m["completed"], m["trials"]) for m in done] == [("0", "2", "4"), ("1", "4", "4")]
    assert done[-1]["eta"] == "0:00:00" and done[0]["best"] != "none yet"
    for gen in ("0", "1"):  # each generation's training is seen, its end (100%) included
        assert [m["pct"] for _, m in progress if m["gen"] == gen and m["pct"]][-1] == "100"
    assert lines[progress[-1][0] + 1].startswith("best fitness ")


def train_progress(fraction: float) -> Progress:
    total = 8192
    return Progress(iteration=int(4 * fraction), n_iterations=4, agent_steps=int(total * fraction),
                    total_agent_steps=total, elapsed_s=2.0 * fraction, compile_s=10.0)


def test_lines_are_held_back_to_one_per_interval_but_phase_ends_always_print():
    for interval_s, shown in ((math.inf, ["25%", "100%"]), (0.0, ["25%", "50%", "75%", "100%"])):
        out = io.StringIO()  # not a terminal
        with TrainingBar("CartPole-v1", console=Console(file=out), interval_s=interval_s) as bar:
            for fraction in (0.25, 0.5, 0.75, 1.0):
                bar.update(train_progress(fraction))
        lines = out.getvalue().splitlines()
        assert lines[0] == "CartPole-v1: compiling"
        assert [re.search(r"\((\d+%)\)", line)[1] for line in lines[1:]] == shown
        assert lines[-1] == ("CartPole-v1: 8k/8k steps (100%) | 4,096 agent-steps/s | elapsed 0:00:02 + compile "
                             "10 s | ETA 0:00:00")


def test_a_held_back_line_is_printed_when_the_display_closes():
    out = io.StringIO()
    with TrainingBar("x", console=Console(file=out), interval_s=math.inf) as bar:
        bar.update(train_progress(0.25))
        bar.update(train_progress(0.5))  # interrupted here
    assert [re.search(r"\((\d+%)\)", line)[1] for line in out.getvalue().splitlines()[1:]] == ["25%", "50%"]


def test_every_told_generation_prints_a_line():
    out = io.StringIO()
    with EvolutionBar(total_trials=4, popsize=2, console=Console(file=out), interval_s=math.inf) as bar:
        for gen in (0, 1):
            for fraction in (0.5, 1.0):
                bar.update(GenerationProgress(gen, "CartPole-v1", 2 * gen, 4, None if gen == 0 else 20.0,
                                              None if gen == 0 else {"sr": 0.5, "lr": 0.1}, train_progress(fraction)))
            bar.update(GenerationProgress(gen, "CartPole-v1", 2 * gen + 2, 4, 20.0, {"sr": 0.5, "lr": 0.1}, None))
    lines = out.getvalue().splitlines()
    assert all(GEN_LINE.fullmatch(line) for line in lines), lines
    assert [GEN_LINE.fullmatch(line)["pct"] or "done" for line in lines] == ["50", "100", "done", "100", "done"]
    assert lines[2].startswith("gen 0 | 2/4 trials | best 20.0 (sr 0.5, leak rate 0.1) | generation done")
    assert lines[-1].endswith("study ETA 0:00:00")


def test_a_terminal_still_gets_the_live_bar():
    out = io.StringIO()
    with TrainingBar("CartPole-v1", console=Console(file=out, force_terminal=True)) as bar:
        bar.update(train_progress(1.0))
    assert "\x1b[" in out.getvalue()  # drawn in place, with control codes
    assert "CartPole-v1: compiling" not in out.getvalue() and "agent-steps/s |" not in out.getvalue()
