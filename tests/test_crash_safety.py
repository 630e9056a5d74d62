"""Crash safety as a user meets it: `kill -9` at many random points of an evolution, each followed by a resume,
and of `ermrl train` and `ermrl test`, each followed by a rerun. Real processes, a real SQLite study.

An evolution may lose only the trials in flight: after every kill the completed trials are the ones completed
before it plus those the killed process finished, never more than --trials, each complete (its fitness and user
attributes) and counted once; the last, uninterrupted resume ends with exactly --trials. A run folder is absent
or complete after a kill, never half-written. The kill points are drawn from a seeded RNG over three moments:
start-up (imports, opening or creating the study, compiling), mid-generation (training), and the tells (the
trials' attributes and states going into the storage), found by watching the study file.
"""

import dataclasses
import random
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

from ermrl import agent_files, storage
from ermrl.errors import TERMINATED

from cli_runs import COMMAND

POPSIZE = 4
TINY = ["--seeds", "1", "--timesteps", "512"]
"""One PPO iteration per agent: SB3 stops at the first whole rollout past --timesteps, so 512 trains one rollout of
its 2048 steps (``PPOConfig.iterations``). The default reservoir, whose programs many tests compile: a generation
trains in about a second once compiled."""
EVOLVE = ["evolve", "--env", "CartPoleNoVel-v1", *TINY, "--popsize", str(POPSIZE), "--study", "k", "--no-estimate",
          "--quiet"]
WORKER = ["--heartbeat-interval", "1", "--grace-period", "3"]
"""The workers' heartbeats: a trial whose worker's process is not seen gone (it had not recorded itself yet) is
failed after 3 s without a heartbeat instead of the default 60 s."""
WATCHDOG_S = 600


def cli(*args) -> list[str]:
    return [*COMMAND, *args]


def counts(db: Path) -> dict[str, tuple[int, int]] | None:
    """{state: (trials, largest trial number)} read from the study file without blocking its writer (read-only,
    50 ms lock timeout); None while it cannot be read (missing, being created, locked)."""
    try:
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=0.05)
        try:
            rows = con.execute("SELECT state, COUNT(*), MAX(number) FROM trials GROUP BY state").fetchall()
        finally:
            con.close()
    except sqlite3.Error:
        return None
    return {state: (n, top) for state, n, top in rows}


@dataclasses.dataclass
class KillPoint:
    """Kill the process ``delay_s`` after ``moment``: "start" (its launch), "train" (the first trial it asks
    is RUNNING: mid-generation) or "tell" (the first trial it tells is COMPLETE: mid-tell or just after)."""

    moment: str
    delay_s: float


def kill_points(n: int, seed: int) -> list[KillPoint]:
    """``n`` kill points, a fifth at start-up, the rest split between training and telling, in a seeded order."""
    rng = random.Random(seed)
    starts = max(1, n // 5)
    moments = ["start"] * starts + ["train"] * ((n - starts) // 2) + ["tell"] * (n - starts - (n - starts) // 2)
    rng.shuffle(moments)
    ranges = {"start": (0.3, 8.0), "train": (0.0, 2.0), "tell": (0.0, 0.3)}
    return [KillPoint(m, round(rng.uniform(*ranges[m]), 3)) for m in moments]


def study_trigger(point: KillPoint, db: Path):
    """A function telling whether ``point``'s moment has come for a worker launched now on the study file ``db``."""
    launch = counts(db) or {}
    top = max((t for _, t in launch.values()), default=-1)
    done = launch.get("COMPLETE", (0, 0))[0]
    if point.moment == "start":
        return lambda: True
    if point.moment == "train":  # a trial numbered above every trial that existed at launch is running
        return lambda: (c := counts(db)) is not None and c.get("RUNNING", (0, -1))[1] > top
    return lambda: (c := counts(db)) is not None and c.get("COMPLETE", (0, 0))[0] > done


def folder_trigger(point: KillPoint, folder: Path):
    """A function telling whether ``point``'s moment ("start", or "write": the command has written its first file
    of ``folder``, staged beside it or in place) has come for a command launched now."""
    existed = folder.exists()
    if point.moment == "start":
        return lambda: True

    def writing():
        staged = folder.parent.glob(f".{folder.name}.partial-*/*")
        return (not existed and folder.exists()) or next(staged, None) is not None

    return writing


def run_and_kill(cmd: list[str], cwd: Path, point: KillPoint, trigger,
                 sig: int = signal.SIGKILL) -> tuple[bool, subprocess.CompletedProcess]:
    """Starts ``cmd`` and sends it ``sig`` (default SIGKILL) ``point.delay_s`` after ``trigger()`` first holds;
    returns (stopped by it, the finished process). A process that ends before its kill point must succeed."""
    out, err = cwd / "stdout.txt", cwd / "stderr.txt"
    with open(out, "w") as fo, open(err, "w") as fe:
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=fo, stderr=fe)
        start, fired = time.monotonic(), None
        while proc.poll() is None:
            elapsed = time.monotonic() - start
            assert elapsed < WATCHDOG_S, f"{cmd} still running after {WATCHDOG_S} s"
            if fired is None and trigger():
                fired = elapsed
            if fired is not None and elapsed >= fired + point.delay_s:
                proc.send_signal(sig)
                proc.wait(timeout=WATCHDOG_S)
                break
            time.sleep(0.002)
    result = subprocess.CompletedProcess(cmd, proc.returncode, out.read_text(), err.read_text())
    killed = proc.returncode in (-sig, TERMINATED if sig == signal.SIGTERM else -sig)
    assert killed or proc.returncode == 0, result.stderr
    return killed, result


@dataclasses.dataclass
class Snapshot:
    """What a study holds after one kill."""

    complete: dict[int, float]
    """{trial number: value} of the COMPLETE trials."""
    running: int
    failed: int
    per_generation: dict[int, int]
    """COMPLETE trials per generation."""
    params: list[tuple]
    unexplained: list[int]
    """COMPLETE trials missing a user attribute of a told trial, or FAIL trials without a failure reason."""


def snapshot(db: Path, seeds: int = 1) -> Snapshot | None:
    """The study as the next worker will find it; None when the killed process had not created it yet."""
    if not db.exists():
        return None
    storage_ = optuna.storages.RDBStorage(f"sqlite:///{db}")
    try:
        try:
            study = optuna.load_study(study_name="k", storage=storage_)
        except KeyError:
            return None
        trials = study.get_trials(deepcopy=False)
    finally:
        storage_.engine.dispose()
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    per_generation: dict[int, int] = {}
    unexplained = []
    for t in complete:
        a = t.user_attrs
        told = (isinstance(a.get("generation"), int) and "phi" in a and len(a.get("seed_fitness", ())) == seeds
                and np.isfinite(t.value) and np.isclose(np.mean(a["seed_fitness"]), t.value))
        if not told:
            unexplained.append(t.number)
        per_generation[a.get("generation")] = per_generation.get(a.get("generation"), 0) + 1
    unexplained += [t.number for t in trials if t.state == TrialState.FAIL and not t.user_attrs.get("failure")]
    return Snapshot({t.number: t.value for t in complete}, sum(t.state == TrialState.RUNNING for t in trials),
                    sum(t.state == TrialState.FAIL for t in trials), per_generation,
                    [tuple(sorted(t.params.items())) for t in complete], unexplained)


def check(snap: Snapshot | None, before: Snapshot | None, trials: int) -> None:
    """The invariants after every kill: nothing completed is lost or changed, nothing counted twice, never
    more than ``trials`` completed, each completed trial fully told, at most one generation in flight."""
    if snap is None:
        assert before is None, "the study disappeared"
        return
    assert len(snap.complete) <= trials
    assert not snap.unexplained, f"trials half-told or failed without a reason: {snap.unexplained}"
    assert all(n <= POPSIZE for n in snap.per_generation.values()), snap.per_generation
    assert len(set(snap.params)) == len(snap.params), "the same Φ completed twice"
    assert snap.running <= POPSIZE, f"{snap.running} trials RUNNING"
    if before is not None:
        kept = {n: v for n, v in snap.complete.items() if n in before.complete}
        assert kept == before.complete, "a completed trial was lost or changed"


def kill_and_resume(folder: Path, points: list[KillPoint], trials: int) -> list[tuple]:
    """Runs an evolution of ``trials`` trials in ``folder`` (run folder ``folder/run``), killed at each point in
    turn (each kill followed by a resume, which the next point kills), then resumes it to the end. Checks the
    study after every kill; returns (point, whether it was killed, the study after it: a Snapshot or None)."""
    db = folder / "run" / "study.db"
    cmd = cli(*EVOLVE, "--trials", str(trials), "--out", str(folder / "run"), *WORKER)
    history, before = [], None
    for point in points:
        killed, _ = run_and_kill(cmd, folder, point, study_trigger(point, db))
        snap = snapshot(db)
        check(snap, before, trials)
        history.append((point, killed, snap))
        print(point, "killed" if killed else "finished", snap and (len(snap.complete), snap.running, snap.failed))
        before = snap or before
    final = subprocess.run(cmd, cwd=folder, capture_output=True, text=True, timeout=WATCHDOG_S)
    assert final.returncode == 0, final.stderr
    snap = snapshot(db)
    check(snap, before, trials)
    assert len(snap.complete) == trials and snap.running == 0
    history.append((None, False, snap))
    return history


@pytest.fixture(scope="module")
def killed_evolution(tmp_path_factory):
    """An evolution of 42 trials (not a multiple of popsize: its last generation is short) killed at 10 random
    points, each followed by a resume, then resumed to the end: (its folder, the history of
    :func:`kill_and_resume`)."""
    folder = tmp_path_factory.mktemp("evolution")
    return folder, kill_and_resume(folder, kill_points(10, seed=11), trials=42)


def test_kill_9_at_ten_random_points_of_an_evolution_loses_only_the_trials_in_flight(killed_evolution):
    _, history = killed_evolution  # each kill's study was checked as it happened (see check)
    killed = [(p, s) for p, k, s in history if k]
    assert len(killed) == 10  # no process finished before its kill point
    assert {p.moment for p, _ in killed} == {"start", "train", "tell"}
    assert any(s is not None and 0 < len(s.complete) < 42 for _, s in killed)
    final = history[-1][2]
    assert len(final.complete) == 42 and final.running == 0
    assert final.failed >= sum(s is not None and s.running > 0 for _, s in killed)  # each was failed, with a reason


def test_an_evolution_on_a_journal_with_a_torn_tail_resumes(tmp_path):
    """What a writer killed mid-append or a full disk leaves; the resume cuts it instead of gluing onto it."""
    cmd = cli(*EVOLVE, "--trials", "4", "--storage", "run/studies.log", "--out", "run", *WORKER)
    assert subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600).returncode == 0
    log = tmp_path / "run" / "studies.log"
    log.write_bytes(log.read_bytes()[:-20])
    cmd[cmd.index("--trials") + 1] = "8"
    r = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    trials = optuna.load_study(study_name="k", storage=optuna.storages.JournalStorage(
        optuna.storages.journal.JournalFileBackend(str(log)))).trials
    assert sum(t.state == TrialState.COMPLETE for t in trials) == 8


TEST = ["test", "--study", "k", "--out", "run", "--seeds", "2", "--timesteps", "512", "--quiet"]
"""The test phase of the killed evolution: ER-MRL and PPO on the same and on the full observation, 2 seeds each, at
a tiny budget."""


def check_test_phase(folder: Path) -> bool:
    """Whether a test phase's folder exists; asserts that it is then complete (every file whole and readable)."""
    if not folder.exists():
        return False
    rows = storage.read_json(folder / "summary.json")
    assert [r["model"].split(" (")[0] for r in rows] == ["ER-MRL", "PPO", "PPO"]
    assert (folder / "summary.csv").read_text().count("\n") == 4
    curves = storage.read_curves_csv(folder / "curves.csv")
    assert sorted(len(v) for _, v in curves.values()) == [2, 2, 2]
    assert storage.read_json(folder / "test_config.json")["seeds"] == 2
    assert _whole_png(folder / "test_phase.png") and (folder / "test_phase.svg").read_text().rstrip().endswith("</svg>")
    agents = agent_files.find_agents(folder)
    assert len(agents) == 6 and all(agent_files.read_agent(a)[0]["seed"] in (1000, 1001) for a in agents)
    return True


def _whole_png(path: Path) -> bool:
    data = path.read_bytes()
    return data[:8] == b"\x89PNG\r\n\x1a\n" and data[-8:-4] == b"IEND"


def kill_command(cmd: list[str], cwd: Path, folder: Path, points: list[KillPoint], complete) -> list[bool]:
    """Kills ``cmd`` (which writes ``folder``) at each point; after each kill (or run, where it ended before its
    point) ``folder`` must be absent or ``complete``; then reruns it to the end, after which no staging folder is
    left. Returns whether ``folder`` was there after each point."""
    present = []
    for point in points:
        killed, _ = run_and_kill(cmd, cwd, point, folder_trigger(point, folder))
        present.append(complete(folder))
        assert killed or present[-1]
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=WATCHDOG_S)
    assert r.returncode == 0, r.stderr
    assert complete(folder)
    assert not list(folder.parent.glob(f".{folder.name}.partial-*"))
    return present


def test_kill_9_while_a_test_phase_writes_leaves_it_absent_then_report_and_plot_work(killed_evolution):
    folder, _ = killed_evolution
    kill_command(cli(*TEST), folder, folder / "run" / "test", [KillPoint("write", 0.0)], check_test_phase)
    r = subprocess.run(cli("report", "--study", "k", "--out", "run"), cwd=folder, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    html = (folder / "run" / "report.html").read_text()
    assert "ER-MRL" in html and html.count("<img") >= 2
    r = subprocess.run(cli("plot", "run/test", "--out", "curves.png"), cwd=folder, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    assert _whole_png(folder / "curves.png")


TRAIN = ["train", "--env", "CartPoleNoVel-v1", "--seeds", "2", "--timesteps", "1024", "--out", "run", "--quiet"]


def check_train_run(folder: Path) -> bool:
    """Whether a train run folder exists; asserts that it is then complete."""
    if not folder.exists():
        return False
    assert storage.read_json(folder / "config.json")["population"]["seeds"] == [0, 1]
    assert len(storage.read_json(folder / "summary.json")["fitness"]) == 2
    assert [len(v) for _, v in storage.read_curves_csv(folder / "curves.csv").values()] == [2]
    assert (folder / "episodes.csv").read_text().startswith("model,agent,seed,timestep,return,length\n")
    assert _whole_png(folder / "learning_curve.png")
    agents = agent_files.find_agents(folder)
    assert [agent_files.read_agent(a)[0]["seed"] for a in agents] == [0, 1]
    return True


def random_points(n: int, seed: int, start_s: tuple[float, float]) -> list[KillPoint]:
    """``n`` kill points of a command that writes a folder, alternately while writing and at a random time."""
    rng = random.Random(seed)
    return [KillPoint("start", round(rng.uniform(*start_s), 3)) if i % 2 else
            KillPoint("write", round(rng.uniform(0, 0.3), 3)) for i in range(n)]


def test_train_killed_or_refused_a_write_while_writing_leaves_no_run_folder(tmp_path):
    """Killed while it writes its run folder: no run folder, only its hidden staging folder. Rerun with a file size
    limit (RLIMIT_FSIZE, 20 kB) standing for a full disk: the first file over it (an agent file, ≈ 90 kB) is refused
    (EFBIG); one line, exit 1, no run folder, and no staging folder (the killed one's removed too). A rerun without
    the limit writes it whole."""
    import resource

    run, point = tmp_path / "run", KillPoint("write", 0.0)
    killed, _ = run_and_kill(cli(*TRAIN), tmp_path, point, folder_trigger(point, run))
    assert killed and not run.exists() and len(list(tmp_path.glob(".run.partial-*"))) == 1

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))

    r = subprocess.run(cli(*TRAIN), cwd=tmp_path, capture_output=True, text=True, timeout=600, preexec_fn=limit)
    last = r.stderr.splitlines()[-1]  # above it, JAX's warnings that its compilation cache could not be written
    assert r.returncode == 1 and last == ("ermrl train: error: File too large; free some space or give another "
                                          "output path, then rerun (files are written whole or not at all, and a "
                                          "study keeps every trial told before)"), r.stderr
    assert not run.exists() and not list(tmp_path.glob(".run.partial-*"))
    kill_command(cli(*TRAIN), tmp_path, run, [], check_train_run)


@pytest.mark.slow
def test_kill_9_at_thirty_random_points_of_an_evolution_loses_only_the_trials_in_flight(tmp_path):
    points = kill_points(30, seed=12)
    history = kill_and_resume(tmp_path, points, trials=122)
    assert sum(k for _, k, _ in history) == len(points)
    assert len(history[-1][2].complete) == 122


@pytest.mark.slow
def test_kill_9_at_ten_random_points_of_train_leaves_its_run_folder_absent_or_complete(tmp_path):
    kill_command(cli(*TRAIN), tmp_path, tmp_path / "run", [], check_train_run)
    (tmp_path / "run" / "context.png").write_bytes(b"another command's output")
    for point in random_points(10, seed=15, start_s=(0.5, 12.0)):  # each kill followed by a rerun to the end
        kill_command(cli(*TRAIN), tmp_path, tmp_path / "run", [point], check_train_run)
    assert (tmp_path / "run" / "context.png").read_bytes() == b"another command's output"  # kept by every rerun


@pytest.mark.slow
def test_kill_9_at_four_random_points_of_a_test_phase_leaves_it_absent_or_complete(killed_evolution):
    folder, _ = killed_evolution
    for point in random_points(4, seed=16, start_s=(2.0, 15.0)):
        kill_command(cli(*TEST), folder, folder / "run" / "test", [point], check_test_phase)
