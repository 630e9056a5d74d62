"""A study as it stood after generation G, copied to another storage, to select and test a study still evolving.

`ermrl select` records its re-evaluations in the study it reads, and the evolution's own selection comes when it
ends; selecting on the live study would leave an early selection there for the end to find. This script copies
the ermrl record and the COMPLETE and FAIL trials of generations 0..G into a new study of the same name in
another storage (a journal file that must not hold that study), where `ermrl select` and `ermrl test` run as on
any study. Only whole generations are copied: G must have all its trials complete.

Usage:
    .venv/bin/python paper/study_so_far.py --study NAME --storage journal:FROM.log --generation G --to journal:TO.log
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--study", required=True)
    p.add_argument("--storage", required=True, help="the study's storage URL or journal:PATH")
    p.add_argument("--generation", type=int, required=True, help="the last generation to copy")
    p.add_argument("--to", required=True, help="a storage without that study (journal:PATH)")
    a = p.parse_args(argv)

    import optuna
    from optuna.trial import TrialState

    from ermrl.evolution.generations import ATTR as GENERATION
    from ermrl.evolution.record import decode_study_record
    from ermrl.evolution.study import ATTR, copy_trials, load_study, make_storage

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = load_study(a.storage, a.study)
    size = decode_study_record(study.user_attrs[ATTR]).generation_size
    trials = study.get_trials(deepcopy=False)
    last = [t for t in trials if int(t.user_attrs.get(GENERATION, -1)) == a.generation
            and t.state == TrialState.COMPLETE]
    if a.generation < 0 or len(last) < size:
        p.error(f"generation {a.generation} of {a.study!r} has {len(last)} of its {size} trials complete; "
                "give a generation the study has finished")
    if a.study in {s.study_name for s in optuna.get_all_study_summaries(make_storage(a.to, heartbeat=None))}:
        p.error(f"{a.to} already holds a study {a.study!r}; give --to another storage")
    kept = [t for t in trials if t.state in (TrialState.COMPLETE, TrialState.FAIL)
            and int(t.user_attrs.get(GENERATION, 0)) <= a.generation]
    copy_trials(study, kept, a.to)
    done = sum(t.state == TrialState.COMPLETE for t in kept)
    print(f"copied {len(kept)} trials ({done} complete) of generations 0–{a.generation} of {a.study!r} to {a.to}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
