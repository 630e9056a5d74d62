"""A worker standing still inside a storage transaction (ermrl/evolution/rdb.py; docs/scaling.md, "Heartbeats"):
a real PostgreSQL server, a real stopped process, sessions ended by the server."""

import signal
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import optuna
import pytest
from optuna.trial import TrialState

from ermrl.evolution.heartbeat import WORKER_ATTR, WorkerId, fail_lost
from ermrl.evolution.study import make_sampler, make_storage, open_study
from test_workers import LOST, _wait_for


STOPPED_INSIDE_A_TELL = """
import os, signal, sys
import sqlalchemy
from optuna.exceptions import UpdateFinishedTrialError
from optuna.trial import TrialState
from ermrl.evolution.study import make_storage

url, trial_id = sys.argv[1], int(sys.argv[2])
storage = make_storage(url, (1, 3))  # as a worker opens it: heartbeats every 1 s, grace period 3 s
stopped = []


def stop_once_locked(conn, cursor, statement, *args):
    if "FOR UPDATE" in statement and not stopped:
        stopped.append(statement)
        print("locked", flush=True)
        os.kill(os.getpid(), signal.SIGSTOP)  # frozen here, inside the transaction, the trial's row locked


sqlalchemy.event.listen(storage.engine, "after_cursor_execute", stop_once_locked)
try:
    storage.set_trial_state_values(trial_id, TrialState.COMPLETE, [1.0])  # a tell
    print("told", flush=True)
except UpdateFinishedTrialError:
    print("run again, it found the trial", storage.get_trial(trial_id).state.name, flush=True)
"""


def test_a_worker_stopped_inside_a_transaction_blocks_nobody_past_the_grace_period(postgres_url):
    """A worker frozen (SIGSTOP, a machine cut off) in the middle of a tell holds the trial's row lock; another
    worker failing that trial would wait on it for ever. PostgreSQL ends such a session once it has stood idle for
    the grace period (``idle_in_transaction_session_timeout``), so the trial is failed as lost soon after; thawed,
    the frozen worker's tell fails with the ended session, runs again on a new connection, and finds the trial
    failed (as a worker frozen between two calls does: it then drops the result with a log line)."""
    study = open_study(postgres_url, "stuck", make_sampler("random", 2, 0), None, heartbeat=(1, 3))
    with warnings.catch_warnings():  # Optuna's heartbeats are meant for Study.optimize; workers beat by hand
        warnings.simplefilter("ignore", UserWarning)
        trial = study.ask()
    study._storage.record_heartbeat(trial._trial_id)
    trial.set_user_attr(WORKER_ATTR, {"host": "elsewhere", "machine": "?", "pid": 1, "index": 1, "token": "x"})
    child = subprocess.Popen([sys.executable, "-c", STOPPED_INSIDE_A_TELL, postgres_url, str(trial._trial_id)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline() == "locked\n"
        _wait_for(lambda: Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "T",
                  "the worker to stop")
        lines = []
        me = WorkerId.here(0)
        survivor = threading.Thread(daemon=True, target=lambda: _wait_for(
            lambda: fail_lost(study, study.get_trials(deepcopy=False), me, 3, lines.append), "a stale heartbeat"))
        survivor.start()
        survivor.join(timeout=60)
        assert not survivor.is_alive(), "the stopped worker's row lock blocked the survivor for 60 s"
    finally:
        child.send_signal(signal.SIGCONT)
    assert lines == [f"trial 0 failed: {LOST}; it will be redone"]
    out, err = child.communicate(timeout=60)
    assert (child.returncode, out) == (0, "run again, it found the trial FAIL\n"), err


@pytest.mark.parametrize("call, after", [("tell", "FOR UPDATE"), ("read", "ORDER BY trials.trial_id")])
def test_a_storage_call_whose_connection_the_server_ended_runs_once_more(postgres_url, call, after):
    """A storage call whose session the server ends mid-transaction (``pg_terminate_backend`` right after a tell's
    SELECT ... FOR UPDATE, or after a read's query of the trials, before it loads their attributes: Optuna tries
    that read again on the broken session itself) runs once more on a new connection: the tell lands once, the
    read returns the trials."""
    import psycopg
    import sqlalchemy

    study = open_study(postgres_url, "ended", make_sampler("random", 2, 0), None, heartbeat=(1, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        trial = study.ask()
    trial.set_user_attr("generation", 0)
    backend = study._storage._backend
    seen = []

    def end_the_first(conn, cursor, statement, *args):
        if after in statement:
            seen.append(cursor.connection.info.backend_pid)
            if len(seen) == 1:
                with psycopg.connect(postgres_url, autocommit=True) as admin:
                    admin.execute("SELECT pg_terminate_backend(%s)", (seen[0],))

    sqlalchemy.event.listen(backend.engine, "after_cursor_execute", end_the_first)
    try:
        if call == "tell":
            study.tell(trial, 1.0)
        else:
            read = backend._get_trials(study._study_id, None, set(), -1)
    finally:
        sqlalchemy.event.remove(backend.engine, "after_cursor_execute", end_the_first)
    assert seen[0] not in seen[1:] and len(seen) >= 2  # run again, on a new connection
    if call == "read":
        assert [(t.state, t.user_attrs) for t in read] == [(TrialState.RUNNING, {"generation": 0})]
    told = optuna.load_study(study_name="ended", storage=make_storage(postgres_url)).trials  # read afresh
    assert [(t.state, t.value) for t in told] == ([(TrialState.COMPLETE, 1.0)] if call == "tell" else
                                                   [(TrialState.RUNNING, None)])
