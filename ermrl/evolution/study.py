"""Optuna storage and studies: opening them with one-line errors, and what ermrl keeps in them.

The default storage is an embedded SQLite file in the run folder. Any Optuna RDB URL works (``postgresql://``
through psycopg, the ``workers`` extra, for many workers on one study: docs/scaling.md), and so does a journal
file (a path ending in ``.log`` or ``.jsonl``, or ``journal:PATH``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import optuna

from ermrl import provenance
from ermrl.errors import ConfigError
from ermrl.evolution.heartbeat import GRACE_PERIOD_S, INTERVAL_S
from ermrl.evolution.rdb import driver_missing, rdb_storage

SAMPLERS = ("cmaes", "random", "tpe")
ATTR = "ermrl"
"""The study user attribute that holds the evolution's config."""
SOFTWARE_ATTR = "software"
"""The study user attribute that holds the software versions it started with (:mod:`ermrl.provenance`)."""


def default_storage(run_dir: Path) -> str:
    return f"sqlite:///{run_dir / 'study.db'}"


def storage_file(url: str) -> Path | None:
    """The file behind a SQLite URL or a journal file; None for a database server."""
    if url.startswith("journal:") or url.endswith((".log", ".jsonl")):
        return Path(url.removeprefix("journal:"))
    if url.startswith("sqlite:///"):
        return Path(url.removeprefix("sqlite:///"))
    return None


def make_storage(url: str, heartbeat: tuple[int, int] | None = None) -> optuna.storages.BaseStorage:
    """An Optuna storage for ``url``; raises ConfigError (one line) if it cannot be opened. ``heartbeat``:
    (interval, grace period) in seconds, Optuna's heartbeats of an RDB storage (see ``heartbeat.py``); journal
    files have none in Optuna, and ermrl's workers beat there through a trial attribute instead."""
    journal = url.startswith("journal:") or url.endswith((".log", ".jsonl"))
    try:
        if journal:
            path = storage_file(url)
            path.parent.mkdir(parents=True, exist_ok=True)
            from ermrl.atomic import repair_journal

            repair_journal(path)  # a torn last line (a writer killed mid-append, a full disk) would poison the next append
            return optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(path)))
        if url.startswith("sqlite:///"):
            Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
        if driver_missing(url):
            raise ConfigError(f"cannot open storage {shown_url(url)!r}: the PostgreSQL driver is not installed; run "
                              "pip install 'ermrl[workers]'")
        return rdb_storage(url, heartbeat)
    except ConfigError:
        raise
    except Exception as e:  # sqlalchemy raises many types; all mean the URL is unusable
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ConfigError(f"cannot open storage {shown_url(url)!r} ({reason}); use sqlite:///PATH.db, a journal file PATH.log, "
                          "or a reachable database URL") from None


def shown_url(url: str) -> str:
    """``url`` as printed or put in a message: a database server's password replaced by ``***``; files as they are."""
    if url.startswith("journal:") or url.endswith((".log", ".jsonl")) or url.startswith("sqlite:"):
        return url
    from sqlalchemy.engine import make_url

    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # not a URL SQLAlchemy can parse: hide whatever sits between "user:" and "@"
        import re

        return re.sub(r"(://[^:/@]*:)[^@]*@", r"\1***@", url)


def make_sampler(name: str, popsize: int, seed: int | None) -> optuna.samplers.BaseSampler:
    """Optuna's CmaEsSampler with its defaults (the paper), or random, or TPE."""
    if name == "cmaes":
        return optuna.samplers.CmaEsSampler(popsize=popsize, seed=seed, warn_independent_sampling=False)
    if name == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    if name == "tpe":
        return optuna.samplers.TPESampler(seed=seed)
    raise ConfigError(f"unknown sampler {name!r}; choose one of {', '.join(SAMPLERS)}")


def open_study(storage_url: str, name: str, sampler, record: dict | None,
               heartbeat: tuple[int, int] | None = (INTERVAL_S, GRACE_PERIOD_S)) -> optuna.Study:
    """Creates or resumes study ``name``. With ``record``, checks that a resumed study has the same config.
    ``heartbeat``: (interval, grace period) in seconds of Optuna's heartbeats on an RDB storage, which every
    worker of a study must have (see ``heartbeat.py``)."""
    storage = make_storage(storage_url, heartbeat)
    try:
        try:  # load first: creating an existing study would append a (refused) creation to a journal file each time
            study = optuna.load_study(study_name=name, storage=storage, sampler=sampler)
        except KeyError:
            study = optuna.create_study(storage=storage, study_name=name, sampler=sampler, direction="maximize",
                                        load_if_exists=True)
    except Exception as e:
        raise ConfigError(f"cannot open study {name!r} in {shown_url(storage_url)!r} ({str(e).splitlines()[0]})") from None
    if record is not None:
        stored = study.user_attrs.get(ATTR)
        if stored is None:
            study.set_user_attr(ATTR, record)
            stored = study.user_attrs[ATTR]  # a worker started at the same moment may have written its own
            differs = _comparable(stored) != _comparable(record)
        else:
            differs = _comparable(_current(stored)) != _comparable(record)
        if differs:
            raise ConfigError(f"study {name!r} already exists with another config; rerun with the same flags to "
                              "resume it, or pick a new --study name")
        _record_software(study, name)
    return study


def _record_software(study: optuna.Study, name: str) -> None:
    """Keeps the software versions of the first run that opened the study (:mod:`ermrl.provenance`; studies
    older than this record get the versions of their next run) in its user attribute
    ``software``; a resumption under other versions warns on stderr, since its trials are then not what one
    run would have computed (other random streams or rounding), though still valid samples of the same method."""
    recorded = study.user_attrs.get(SOFTWARE_ATTR)
    if recorded is None:
        study.set_user_attr(SOFTWARE_ATTR, provenance.software())
    elif changed := provenance.differences(recorded):
        print(f"warning: study {name!r} was started with other versions ({', '.join(changed)}); its new trials "
              "will not match what the first versions would compute, seed for seed", file=sys.stderr)


def load_study(storage_url: str, name: str) -> optuna.Study:
    """An existing ermrl study; ConfigError if it does not exist or was not made by ``ermrl evolve``."""
    path = storage_file(storage_url)
    if path is not None and not path.exists():  # never create an empty database or journal just to look
        raise ConfigError(f"no study {name!r}: {path} does not exist; run `ermrl evolve` first or pass --storage/--out")
    storage = make_storage(storage_url)
    try:
        study = optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        names = [s.study_name for s in optuna.get_all_study_summaries(storage)]
        raise ConfigError(f"no study {name!r} in {shown_url(storage_url)!r}; studies there: {', '.join(names) or 'none'}") from None
    if ATTR not in study.user_attrs:
        raise ConfigError(f"study {name!r} was not made by `ermrl evolve` (no '{ATTR}' attribute)")
    return study


def _current(record: dict) -> dict:
    """A stored record as this version writes it: decoded (fields added since it was written take their
    defaults) and encoded again, so that a study started before a config field existed still resumes."""
    from ermrl import storage

    return storage.encode_study_record(storage.decode_study_record(record))


def _comparable(record: dict) -> str:
    """The config without the fields that may change between a run and its resumption: the trial target, the
    baselines (a resumed study keeps the constants it started with) and the number of env worker processes
    (results do not depend on it). A worker's own settings (``workers.WorkerConfig``: batch, index, heartbeats)
    are not in the record at all."""
    keep = {k: v for k, v in record.items() if k not in ("trials", "baselines")}
    if isinstance(keep.get("train"), dict):
        keep["train"] = {k: v for k, v in keep["train"].items() if k != "env_workers"}
    return json.dumps(keep, sort_keys=True, default=str)
