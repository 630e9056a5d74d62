"""Heartbeats on a journal file (ermrl/evolution/heartbeat.py): a worker writes one heartbeat line per interval
whatever the number of trials it trains, and that line keeps all its trials alive for the other workers."""

import json
import time

import optuna
from optuna.trial import TrialState

from ermrl.evolution.heartbeat import HEARTBEAT_ATTR, WORKER_ATTR, Heartbeat, WorkerId, fail_lost
from ermrl.evolution.study import open_study

optuna.logging.set_verbosity(optuna.logging.WARNING)


def beats_per_trial(journal) -> dict[int, int]:
    """{trial id: heartbeat lines written for it} in a journal file."""
    counts: dict[int, int] = {}
    for line in journal.read_text().splitlines():
        op = json.loads(line)
        if HEARTBEAT_ATTR in op.get("system_attr", {}):
            counts[op["trial_id"]] = counts.get(op["trial_id"], 0) + 1
    return counts


def test_one_heartbeat_line_per_interval_keeps_all_of_a_workers_trials_alive(tmp_path):
    journal = tmp_path / "studies.log"
    study = open_study(f"journal:{journal}", "beats", optuna.samplers.RandomSampler(seed=0), {})
    owner, other = WorkerId.here(0), WorkerId.here(1)
    heartbeat = Heartbeat(study, interval_s=0.2)
    trials = [study.ask() for _ in range(3)]
    for t in trials:  # as Worker._adopt does: beat, then name the worker
        heartbeat.add(t._trial_id)
        t.set_user_attr(WORKER_ATTR, owner.record())
    ids = [t._trial_id for t in trials]
    with heartbeat:
        time.sleep(1.5)
        counts = beats_per_trial(journal)
        # the oldest trial carries the beats; the others were beaten once, when added
        assert counts[ids[1]] == counts[ids[2]] == 1 and 5 <= counts[ids[0]] <= 9, counts
        lines = []
        assert fail_lost(study, study.get_trials(deepcopy=False), other, 1, lines.append) == 0, lines
        study.tell(trials[0], 1.0)  # told: its heartbeat stops, the next oldest trial carries the beats
        heartbeat.remove(ids[0])
        time.sleep(1.5)
        counts = beats_per_trial(journal)
        assert counts[ids[2]] == 1 and counts[ids[1]] >= 5, counts
        assert fail_lost(study, study.get_trials(deepcopy=False), other, 1, lines.append) == 0, lines
    time.sleep(1.5)  # the worker stopped beating: its two RUNNING trials are lost to the others
    assert fail_lost(study, study.get_trials(deepcopy=False), other, 1, lines.append) == 2
    assert lines == [f"trial {n} failed: worker lost (no heartbeat for 1 s); it will be redone" for n in (1, 2)]
    assert [t.state for t in study.get_trials()] == [TrialState.COMPLETE, TrialState.FAIL, TrialState.FAIL]
