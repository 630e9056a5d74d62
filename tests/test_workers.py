"""Many workers on one study: a real PostgreSQL server, real `ermrl evolve` processes, real kills.

The invariants checked after every multi-worker study: exactly --trials COMPLETE trials, none RUNNING, no Φ twice,
every CMA-ES generation but the last holds exactly popsize completed trials (the last one at most popsize), each
trial's generation is the sampler's CMA generation + 1, and the sampler told every CMA generation but the last (its
stored optimizer moved on), so every completed trial beyond the random startup generation informs CMA-ES.
"""

import collections
import os
import pickle
import signal
import subprocess
import time

import optuna
import pytest
from optuna.trial import TrialState

from ermrl import provenance
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.evolve import evolve, make_trainers
from ermrl.evolution.generations import FULL
from ermrl.evolution.heartbeat import INTERRUPTED, WORKER_ATTR
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import load_study, make_sampler, open_study
from ermrl.evolution.worker_config import WorkerConfig
from ermrl.evolution.workers import REDO_ATTR, STALE_REDO, TWICE_REDONE, Worker
from ermrl.evolution.record import encode_study_record
from ermrl.training import TrainConfig

from cli_runs import COMMAND, ermrl

optuna.logging.set_verbosity(optuna.logging.WARNING)

POPSIZE, TRIALS = 6, 24
LOST = "worker lost (no heartbeat for 3 s)"


def evolve_args(timesteps=2048, batch=2) -> list[str]:
    """The workers' evolution: CartPoleNoVel with the default reservoir (the programs of `ermrl train`'s defaults,
    which many tests compile), 1 seed, ``batch`` trials trained at a time."""
    return ["evolve", "--env", "CartPoleNoVel-v1", "--seeds", "1", "--timesteps", str(timesteps), "--fixed-iss", "1.0",
            "--popsize", str(POPSIZE), "--batch", str(batch), "--quiet", "--no-estimate"]


@pytest.fixture(scope="module")
def compiled_once(tmp_path_factory):
    """The workers' population program compiled once, in this process, into the run's persistent compilation cache
    (tests/conftest.py), before a test starts several workers at once: each would otherwise compile it at the same
    moment. Changes when they start training, not what they do."""
    folder = tmp_path_factory.mktemp("compiled-once")
    r = ermrl(*evolve_args(), "--trials", "2", "--storage", f"sqlite:///{folder}/s.db", "--study", "warm", cwd=folder)
    assert r.returncode == 0, r.stderr


def start_worker(url, study, index, folder, timesteps=2048, batch=2, grace=3):
    """One `ermrl evolve` process. A short grace period (3 s) makes lost workers quick to see; tests where no worker
    is lost take a long one, so that a worker starved of CPU by the other tests never looks lost."""
    args = [*evolve_args(timesteps, batch), "--trials", str(TRIALS), "--worker-index", str(index),
            "--heartbeat-interval", "1", "--grace-period", str(grace), "--storage", url, "--study", study, "--debug"]
    out, err = open(folder / f"worker{index}.out", "w"), open(folder / f"worker{index}.err", "w")
    return subprocess.Popen([*COMMAND, *args], stdout=out, stderr=err, cwd=folder)


def finish(procs, folder, timeout=600):
    """Waits for the workers; returns {index: (exit code, stdout, stderr)}."""
    deadline = time.time() + timeout
    for p in procs.values():
        p.wait(timeout=max(1, deadline - time.time()))
    return {i: (p.returncode, (folder / f"worker{i}.out").read_text(), (folder / f"worker{i}.err").read_text())
            for i, p in procs.items()}


def check_study(study):
    """The invariants of the module docstring; returns the trials."""
    trials = study.get_trials(deepcopy=False)
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    assert len(complete) == TRIALS and not [t for t in trials if t.state == TrialState.RUNNING]
    phis = [tuple(sorted(t.params.items())) for t in complete]
    assert len(set(phis)) == len(phis), "a Φ was drawn twice"
    per_generation = collections.Counter(t.user_attrs["generation"] for t in complete)
    last = max(per_generation)
    assert sorted(per_generation) == list(range(last + 1))
    assert all(per_generation[g] == POPSIZE for g in range(1, last)) and per_generation[last] <= POPSIZE
    assert per_generation[0] <= POPSIZE  # fewer when startup trials failed after one completed (see the docs)
    for t in trials:
        tag = t.system_attrs.get("cma:generation")
        if "generation" in t.user_attrs:
            assert t.user_attrs["generation"] == (0 if tag is None else tag + 1)
    carrier = max((t for t in complete if "cma:optimizer:0" in t.system_attrs), key=lambda t: t.number)
    chunks = sorted((k for k in carrier.system_attrs if k.startswith("cma:optimizer:")),
                    key=lambda k: int(k.split(":")[-1]))
    optimizer = pickle.loads(bytes.fromhex("".join(carrier.system_attrs[k] for k in chunks)))
    assert optimizer.generation == last - 1  # every CMA generation but the last told; the last one waits
    return trials, per_generation


def test_three_workers_share_one_study(postgres_url, tmp_path, compiled_once):
    procs = {i: start_worker(postgres_url, "three", i, tmp_path, grace=60) for i in range(3)}
    results = finish(procs, tmp_path)
    for i, (code, out, err) in results.items():
        assert code == 0 and "Traceback" not in err, f"worker {i}: {err}"
    trials, per_generation = check_study(load_study(postgres_url, "three"))
    assert per_generation == {g: POPSIZE for g in range(TRIALS // POPSIZE)}
    workers = {t.user_attrs[WORKER_ATTR]["index"] for t in trials if t.state == TrialState.COMPLETE}
    assert len(workers) >= 2, "the study was not shared"
    cpus = {t.user_attrs[WORKER_ATTR]["cpu"] for t in trials if t.state == TrialState.COMPLETE}
    assert cpus == {provenance.cpu()}  # each trial names the instruction set its numbers were computed with
    assert all(t.user_attrs.get("failure") == FULL for t in trials if t.state == TrialState.FAIL)


def _holding(study, pid, generation=1):
    """Trials RUNNING in the worker process ``pid`` in ``generation`` or later (default: past the random startup)."""
    return [t for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
            if t.user_attrs.get(WORKER_ATTR, {}).get("pid") == pid and t.user_attrs.get("generation", -1) >= generation]


def _wait_for(predicate, what, timeout=300):
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _training(study, procs, generation):
    """(index, held) for the first worker of ``procs`` ({index: Popen}) holding RUNNING trials, else None. Fails at
    once, instead of waiting out the timeout, when the study finished or every candidate exited first."""
    for index, proc in procs.items():
        held = _holding(study, proc.pid, generation)
        if held:
            return index, held
    done = len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
    exited = {i: p.poll() for i, p in procs.items() if p.poll() is not None}
    assert done < TRIALS and len(exited) < len(procs), (
        f"no worker of {sorted(procs)} was seen training (study: {done} trials complete; exited: {exited})")
    return None


def _freeze_while_training(study, procs, generation=1):
    """Stops (SIGSTOP) whichever worker of ``procs`` ({index: Popen}) is first seen holding RUNNING trials (in
    ``generation`` or later; default: past the random startup), whatever share of the trials the scheduler gave each
    worker; returns (index, its trials), stable while it is stopped."""
    while True:
        index, _ = _wait_for(lambda: _training(study, procs, generation), f"one of workers {sorted(procs)} to train")
        start = time.monotonic()
        procs[index].send_signal(signal.SIGSTOP)
        held = _holding(study, procs[index].pid, generation)
        if held and time.monotonic() - start < 1.0:  # well within the grace period: nobody failed them yet
            return index, held
        procs[index].send_signal(signal.SIGCONT)  # it told them in between, or the machine is too slow right now


def _opened(url, name):
    try:
        return load_study(url, name)
    except Exception:  # not created yet, or its record not written yet
        return None


def test_killed_and_frozen_workers_are_replaced(postgres_url, tmp_path, compiled_once):
    """The first of three workers seen training past the startup generation is killed (SIGKILL): on this machine
    its process is seen gone, and its trials are failed ("interrupted") and redone. The next one seen training is
    frozen (SIGSTOP), like a machine cut off: its heartbeats stop, the survivor fails its trials after the grace
    period and redoes them; thawed, it finds them failed, drops their results with a log line, and goes on. The
    study ends with exactly --trials completed. (Which worker is which is left to the scheduler: on a loaded
    machine one worker may get no trial past the startup at all.)"""
    procs = {i: start_worker(postgres_url, "faults", i, tmp_path, timesteps=8192) for i in range(3)}
    study = _wait_for(lambda: _opened(postgres_url, "faults"), "the study")
    running = dict(procs)
    try:
        victim, killed = _freeze_while_training(study, running)
        running.pop(victim).send_signal(signal.SIGKILL)
        procs[victim].wait()
        sleeper, frozen = _freeze_while_training(study, running)
        (survivor,) = set(running) - {sleeper}

        def failed_by_the_survivor():
            code = running[survivor].poll()
            assert code is None, f"the survivor exited ({code}): {(tmp_path / f'worker{survivor}.err').read_text()}"
            return all(study._storage.get_trial(t._trial_id).state == TrialState.FAIL for t in frozen)

        _wait_for(failed_by_the_survivor, "the frozen worker's trials to be failed")
    except BaseException:
        for proc in procs.values():
            proc.kill()
        raise
    finally:
        for proc in running.values():
            proc.send_signal(signal.SIGCONT)
    results = finish(running, tmp_path)
    for i, (code, out, err) in results.items():
        assert code == 0 and "Traceback" not in err, f"worker {i}: {err}"
    trials, _ = check_study(study)
    by_id = {t._trial_id: t for t in trials}
    assert {by_id[t._trial_id].user_attrs["failure"] for t in killed} == {"interrupted"}
    assert {by_id[t._trial_id].user_attrs["failure"] for t in frozen} == {LOST}
    for t in frozen:
        assert f"trial {t.number} was failed meanwhile ({LOST})" in results[sleeper][1]
    assert f"trial {killed[0].number} failed: interrupted; it will be redone" in results[survivor][1] + results[sleeper][1]
    assert {t.user_attrs.get("failure") for t in trials if t.state == TrialState.FAIL} <= \
        {"interrupted", LOST, FULL, STALE_REDO, TWICE_REDONE}


def tiny(trials, popsize=4):
    train = TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048)
    return EvolveConfig(train=train, space=SearchSpace(fixed_iss=1.0), trials=trials, seeds=1, sampler="cmaes",
                        popsize=popsize)


def test_a_stopped_trial_that_two_workers_enqueue_at_once_is_trained_once(tmp_path):
    """Two workers read the study at the same moment and both see the same two trials of CMA-ES generation 1
    stopped (both found the killed worker's process gone), so both enqueue their Φ. The lower-numbered copies are
    trained; the others are failed at once, before they take a slot, and the generation's two other slots get fresh
    draws: no Φ is trained twice. (Before, all four copies fit the generation's four slots: two Φ trained twice.)"""
    config = tiny(trials=12)
    study = open_study(f"journal:{tmp_path / 'studies.log'}", "s", make_sampler("cmaes", 4, 0),
                       encode_study_record(config))
    evolve(study, tiny(trials=4))
    with Worker(study, config, WorkerConfig(batch=2)) as gone:
        stopped = gone.claim().trials
        gone.release(INTERRUPTED)
    seen = study.get_trials(deepcopy=False)
    for index in (1, 2):
        Worker(study, config, WorkerConfig(batch=2, worker_index=index))._redo(seen, 1, 2)
    lines = []
    evolve(study, config, worker=WorkerConfig(batch=2), log=lines.append)
    trials = study.get_trials(deepcopy=False)
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    assert len(complete) == 12 and len({tuple(sorted(t.params.items())) for t in complete}) == 12
    assert [(t.number, t.user_attrs[REDO_ATTR]["trial"], t.params) for t in complete if REDO_ATTR in t.user_attrs] \
        == [(6, 4, stopped[0].params), (7, 5, stopped[1].params)]
    assert [(t.number, t.user_attrs.get("failure")) for t in trials if t.state == TrialState.FAIL] == \
        [(4, INTERRUPTED), (5, INTERRUPTED), (8, TWICE_REDONE), (9, TWICE_REDONE)]
    assert f"trial 8 failed: {TWICE_REDONE} (trial 6)" in lines and f"trial 9 failed: {TWICE_REDONE} (trial 7)" in lines
    assert collections.Counter(t.user_attrs["generation"] for t in complete) == {0: 4, 1: 4, 2: 4}


def test_ctrl_c_fails_the_workers_own_trials(tmp_path):
    """A worker stopped by Ctrl-C fails the trials it holds ("interrupted"), so that a resumption need not wait."""
    config = tiny(trials=4)
    study = open_study(f"sqlite:///{tmp_path}/s.db", "s", make_sampler("cmaes", 4, 0), encode_study_record(config))
    trainers = make_trainers(config)

    def interrupt(p):
        if p.train is not None:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        evolve(study, config, trainers, progress_fn=interrupt, worker=WorkerConfig(batch=2))
    assert [(t.state, t.user_attrs["failure"]) for t in study.trials] == [(TrialState.FAIL, "interrupted")] * 2
    evolve(study, config, trainers, worker=WorkerConfig(batch=2))
    assert [t.state for t in study.trials] == [TrialState.FAIL] * 2 + [TrialState.COMPLETE] * 4


def test_sigterm_fails_the_workers_own_trials(postgres_url, tmp_path, compiled_once):
    """SIGTERM (slurm's time limit, scancel) stops a worker like Ctrl-C: its trials fail ("interrupted"), exit 143.
    (PostgreSQL: on SQLite a worker frozen inside a write would lock this test's reads out.)"""
    url = postgres_url
    proc = start_worker(url, "term", 0, tmp_path, timesteps=8192)
    study = _wait_for(lambda: _opened(url, "term"), "the study")
    _, held = _freeze_while_training(study, {0: proc}, generation=0)
    proc.send_signal(signal.SIGTERM)  # delivered when it runs again
    proc.send_signal(signal.SIGCONT)
    code = proc.wait(timeout=300)
    err = (tmp_path / "worker0.err").read_text()
    assert code == 143 and "Traceback" not in err, f"exit {code}: {err}"
    trials = {t.number: t for t in study.get_trials(deepcopy=False)}
    assert not [t for t in trials.values() if t.state == TrialState.RUNNING]
    assert {trials[t.number].user_attrs.get("failure") for t in held} == {"interrupted"}


@pytest.mark.parametrize("library", ["drops", "replaces"])
def test_a_sigterm_that_a_library_drops_or_replaces_still_stops_the_worker(tmp_path, library):
    """SIGTERM's exception raised inside a library that drops it (as Python does in a garbage collector's callback)
    or replaces it with its own clean-up error (as a database driver may) still stops the worker: exit 143, its
    trials failed "interrupted" (or, if the dropped one came as they finished training, told), no further trials
    claimed, and none failed as a worker error."""
    config = tiny(trials=4)
    study = open_study(f"sqlite:///{tmp_path}/s.db", "s", make_sampler("cmaes", 4, 0), encode_study_record(config))
    handlers = []

    def library_call(p):
        if p.train is None or handlers:
            return
        handlers.append(signal.getsignal(signal.SIGTERM))
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)  # the handler runs here
        except SystemExit:
            if library == "replaces":
                raise RuntimeError("connection lost during clean-up")

    with pytest.raises(SystemExit) as stopped:
        evolve(study, config, make_trainers(config), progress_fn=library_call, worker=WorkerConfig(batch=2))
    assert stopped.value.code == 143 and handlers[0] not in (signal.SIG_DFL, signal.SIG_IGN)
    states = [(t.state, t.user_attrs.get("failure")) for t in study.trials]
    if library == "drops":  # its next check: the next progress report, or (trained already) the next claim
        assert states in ([(TrialState.FAIL, "interrupted")] * 2, [(TrialState.COMPLETE, None)] * 2)
    else:
        assert states == [(TrialState.FAIL, "interrupted")] * 2
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL


@pytest.mark.slow
def test_sigterm_at_any_moment_exits_143_and_leaves_nothing_running(postgres_url, tmp_path, compiled_once):
    """SIGTERM at 20 moments spread over a worker's first 5 s (claiming, compiling, training, telling): every
    time exit 143 and no trial left RUNNING. (Before the worker ended the process at once, about 1 in 10 crashed
    in the interpreter's teardown, racing XLA's threads; 1 in 40 lost the signal in a garbage collector's callback
    and trained on.)"""
    for k in range(20):
        folder = tmp_path / f"w{k}"
        folder.mkdir()
        proc = start_worker(postgres_url, f"w{k}", 0, folder, timesteps=8192)
        study = _wait_for(lambda: _opened(postgres_url, f"w{k}"), "the study")
        _wait_for(lambda: study.get_trials(deepcopy=False), "its first trial")  # its SIGTERM handler is in place
        time.sleep(0.25 * k)
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=300)
        err = (folder / "worker0.err").read_text()
        assert code == 143 and "Traceback" not in err, f"SIGTERM {0.25 * k} s after its first trial: exit {code}: {err}"
        assert not study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))


def test_a_trial_left_running_without_heartbeat_is_failed_after_the_grace_period(tmp_path):
    """A trial left RUNNING by an ermrl version without heartbeats (here: asked the old way, on a journal file) does
    not block the resumed study: once it is older than the grace period it is failed, and its slot redone."""
    config = tiny(trials=4)
    url = f"journal:{tmp_path / 'studies.log'}"
    study = open_study(url, "old", make_sampler("cmaes", 4, 0), encode_study_record(config))
    old = study.ask()
    old.set_user_attr("generation", 0)
    config.space.suggest(old)
    lines = []
    evolve(study, config, worker=WorkerConfig(batch=2, heartbeat_interval=1, grace_period=2), log=lines.append)
    trials = load_study(url, "old").trials
    assert (trials[0].state, trials[0].user_attrs["failure"]) == (TrialState.FAIL, "worker lost (no heartbeat for 2 s)")
    assert [t.state for t in trials[1:]] == [TrialState.COMPLETE] * 4
    assert "trial 0 failed: worker lost (no heartbeat for 2 s); it will be redone" in lines


@pytest.mark.parametrize("args, message", [
    (["--batch", "0"], "--batch must be >= 1, got 0"),
    (["--worker-index", "-1"], "--worker-index must be >= 0, got -1"),
    (["--heartbeat-interval", "10", "--grace-period", "10"],
     "--grace-period (10 s) must be longer than --heartbeat-interval (10 s), or live trials would be failed as lost"),
])
def test_bad_worker_flags(args, message, tmp_path):
    r = ermrl("evolve", "--trials", "2", "--timesteps", "2048", *args, cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, f"ermrl evolve: error: {message}\n")
    assert not list(tmp_path.iterdir())  # nothing written


def test_database_passwords_are_never_printed(postgres_url, tmp_path):
    """A password in a PostgreSQL URL (the server trusts any) is shown as *** in every line and message: the
    evolution's progress and hints, a missing study's error, an unreachable server's error."""
    url = postgres_url.replace("postgresql://ermrl@", "postgresql://ermrl:s3cret@")
    shown = postgres_url.replace("postgresql://ermrl@", "postgresql://ermrl:***@")
    r = ermrl("evolve", "--env", "CartPoleNoVel-v1", "--seeds", "1", "--timesteps", "2048", "--fixed-iss", "1.0",
              "--popsize", "2", "--trials", "2", "--storage", url, "--study", "p", "--quiet", "--no-estimate",
              cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert f"study 'p' in {shown}: 0/2 trials done" in r.stdout and f"--storage {shown}" in r.stdout
    r2 = ermrl("select", "--study", "nope", "--storage", url, cwd=tmp_path)
    assert (r2.returncode, r2.stderr) == (2, f"ermrl select: error: no study 'nope' in '{shown}'; studies there: p\n")
    dead = "postgresql://ermrl:s3cret@127.0.0.1:1/db"
    r3 = ermrl("report", "--study", "p", "--storage", dead, cwd=tmp_path)
    assert r3.returncode == 2 and r3.stderr.startswith(
        "ermrl report: error: cannot open storage 'postgresql://ermrl:***@127.0.0.1:1/db' (")
    assert not any("s3cret" in s for s in (r.stdout, r.stderr, r2.stdout, r2.stderr, r3.stdout, r3.stderr))


def test_two_workers_with_one_index_are_warned_on_stderr(tmp_path, capsys):
    """A live worker (here: this process under another token) runs a trial with --worker-index 0, and a second one
    starts with the same index: the warning goes to stderr, where warnings belong, not into the results on stdout."""
    import time

    from ermrl.evolution.heartbeat import HEARTBEAT_ATTR, WorkerId

    config = tiny(trials=4)
    url = f"journal:{tmp_path / 'studies.log'}"
    study = open_study(url, "twin", make_sampler("cmaes", 4, 0), encode_study_record(config))
    twin = study.ask()
    twin.set_user_attr("generation", 0)
    twin.set_user_attr(WORKER_ATTR, WorkerId.here(0).record())
    study._storage.set_trial_system_attr(twin._trial_id, HEARTBEAT_ATTR, time.time() + 3600)  # alive for the run
    config.space.suggest(twin)
    lines = []
    worker = Worker(study, config, WorkerConfig(batch=2), log=lines.append)
    worker._trials()  # what a worker looks at before each claim
    worker._trials()  # once is enough
    out, err = capsys.readouterr()
    warning = (f"warning: another worker (pid {os.getpid()} on {WorkerId.here(0).host}) also runs with "
               "worker index 0; give each worker its own index, or their sampler draws repeat")
    assert err.count(warning) == 1 and warning not in out and not any("worker-index" in line for line in lines)
