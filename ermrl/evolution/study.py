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
            _check_journal(storage_file(url))
            path = storage_file(url).absolute()  # the lock link's target: a relative one would dangle
            path.parent.mkdir(parents=True, exist_ok=True)
            from ermrl.atomic import journal_lock, repair_journal
            from ermrl.evolution.journal_file import CheckedJournalFile

            repair_journal(path)  # a torn last line (a writer killed mid-append, a full disk) would poison the next append
            backend = CheckedJournalFile(str(path), lock_obj=journal_lock(path))
            return optuna.storages.JournalStorage(backend)
        if url.startswith("sqlite:///"):
            _check_sqlite(storage_file(url))
            storage_file(url).parent.mkdir(parents=True, exist_ok=True)
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


SQLITE_HEADER = b"SQLite format 3\x00"


def _check_journal(path: Path) -> None:
    """ValueError when ``path`` exists, is not empty, and its first line is not an Optuna journal record: Optuna
    would take a one-line file for a torn write and append to it, changing a file that is not a study's."""
    if not path.is_file() or path.stat().st_size == 0:
        return
    with open(path, "rb") as f:
        first = f.readline(1 << 20)
    try:
        record = json.loads(first)
    except ValueError:
        record = None
    if not (isinstance(record, dict) and "op_code" in record):
        raise ValueError(f"{path} is not an Optuna journal: its first line is no journal record")


def _check_sqlite(path: Path) -> None:
    """ValueError when ``path`` exists, is not empty, and is no SQLite database, which SQLite would overwrite."""
    if not path.is_file() or path.stat().st_size == 0:
        return
    with open(path, "rb") as f:
        if f.read(len(SQLITE_HEADER)) != SQLITE_HEADER:
            raise ValueError(f"{path} is not a SQLite database")
    import sqlite3

    try:
        connection = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True)
        try:
            tables = [name for (name,) in connection.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        finally:
            connection.close()
    except sqlite3.Error:
        return  # damaged or locked: the storage's own error, or the damaged-database check, names it
    if tables and "studies" not in tables:
        raise ValueError(f"{path} is a SQLite database of another program (tables {', '.join(sorted(tables)[:3])}), "
                         "not an Optuna study database")


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
        else:
            stored = _current(stored)
        _check_same_config(name, stored, record, open_study)
        _record_software(study, name)
    return study


def check_resumable(storage_url: str, name: str, record: dict) -> None:
    """ConfigError when study ``name`` exists in ``storage_url`` with a config other than ``record``: the check
    of :func:`open_study`, before work that comes first (the baselines of several envs). Creates nothing."""
    path = storage_file(storage_url)
    if path is not None and not path.is_file():
        return
    storage = make_storage(storage_url, heartbeat=None)
    try:
        stored = optuna.load_study(study_name=name, storage=storage).user_attrs.get(ATTR)
    except KeyError:
        return
    if stored is not None:
        _check_same_config(name, _current(stored), record, check_resumable)


def _check_same_config(name: str, stored: dict, record: dict, owner: object) -> None:
    """ConfigError naming the first setting in which the study's config ``stored`` and this run's ``record``
    differ (:func:`_comparable`); ``owner``: the function whose ``name`` the study's name is."""
    a, b = json.loads(_comparable(stored)), json.loads(_comparable(record))
    if a == b:
        return
    shown = [f"{key}: {_shown(was)} in the study, {_shown(now)} here" for key, was, now in _differences(a, b)]
    raise ConfigError(f"study {name!r} already exists with another config ({'; '.join(shown[:3])}"
                      f"{'; ...' if len(shown) > 3 else ''}); rerun with the same settings to resume it, or pick a new "
                      "`name`", owner=owner)


def _differences(a, b, key: str = "") -> list[tuple[str, object, object]]:
    """(dotted key, value in ``a``, value in ``b``) of every leaf where the JSON values ``a`` and ``b`` differ,
    keys in sorted order; a key missing on one side has the value None there."""
    if not (isinstance(a, dict) and isinstance(b, dict)):
        return [(key, a, b)]
    return [d for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)
            for d in _differences(a.get(k), b.get(k), f"{key}.{k}" if key else k)]


def _shown(value) -> str:
    return "unset" if value is None else json.dumps(value)


def check_writable(storage_url: str) -> None:
    """ConfigError before any work when the file behind a SQLite or journal storage cannot be written: its
    folder refuses new files (SQLite writes its journal beside it) or the file cannot be opened for writing
    (a read-only file system, a file of another user). A database server is checked when it is opened."""
    path = storage_file(storage_url)
    if path is None:
        return
    from ermrl.atomic import cannot_write

    folder = next(p for p in path.absolute().parents if p.exists())
    reason = f"{folder} is a file" if not folder.is_dir() else cannot_write(folder)
    if reason is None and path.exists():
        try:
            open(path, "r+b").close()
        except OSError as e:
            reason = f"{path}: {(e.strerror or type(e).__name__).lower()}"
    elif reason is not None and folder.is_dir():
        reason = f"{folder}: {reason}"
    if reason is not None:
        raise ConfigError(f"cannot write storage {shown_url(storage_url)!r} ({reason}); give a storage you can write")


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
        raise ConfigError(f"no study {name!r}: {path} does not exist; run `ermrl evolve` first or pass `storage_url`",
                          owner=load_study)
    if storage_url.startswith("sqlite:///"):  # Optuna would create its tables in any SQLite file, even an empty one
        _check_study_database(storage_url, path)
    storage = make_storage(storage_url)
    try:
        study = optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        names = [s.study_name for s in optuna.get_all_study_summaries(storage)]
        raise ConfigError(f"no study {name!r} in {shown_url(storage_url)!r}; studies there: {', '.join(names) or 'none'}") from None
    if ATTR not in study.user_attrs:
        raise ConfigError(f"study {name!r} was not made by `ermrl evolve` (no '{ATTR}' attribute)")
    return study


DAMAGED = ("malformed", "not a database")
"""What SQLite says of a damaged database file ("database disk image is malformed", "file is not a database")."""


def damaged_database(e: BaseException | None) -> str | None:
    """SQLite's reason when ``e`` or an exception behind it (sqlite3's or SQLAlchemy's DatabaseError, possibly
    wrapped by Optuna) says the database file is damaged (:data:`DAMAGED`); None for anything else."""
    import sqlite3

    while e is not None:
        for error in (e, getattr(e, "orig", None)):  # SQLAlchemy's DatabaseError holds sqlite3's as .orig
            if isinstance(error, sqlite3.DatabaseError) and any(text in str(error) for text in DAMAGED):
                return (str(error).strip().splitlines() or [""])[0]
        e = e.__cause__ or e.__context__
    return None


def damaged_storage_message(storage_url: str, reason: str) -> str:
    """The one-line error for a damaged storage ``storage_url`` (its password hidden)."""
    return f"storage {shown_url(storage_url)!r} is damaged ({reason}); restore it from a copy, or start a new study"


def _check_study_database(storage_url: str, path: Path) -> None:
    """ConfigError unless the SQLite file ``path`` (of ``storage_url``) is a sound database that holds Optuna's
    tables (its ``studies`` table), looked at read-only: opening it as a storage would create them in an empty file
    or in another program's database, which a command that only reads a study must not do; and a damaged page
    (``PRAGMA quick_check``, which reads every page) is named here, before anything is read from it or written.
    Other errors (a locked or unreadable file) are left to the storage to report."""
    import sqlite3

    if not path.is_file():
        return
    if path.stat().st_size == 0:
        raise ConfigError(f"{path} is empty (0 bytes), not a study database; run `ermrl evolve` to create the "
                          "study, or pass `storage_url`", owner=load_study)
    try:
        connection = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True)
        try:
            found = connection.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'studies'")\
                .fetchone()
            check = connection.execute("PRAGMA quick_check(1)").fetchone() if found else ("ok",)
        finally:
            connection.close()
    except sqlite3.DatabaseError as e:
        reason = damaged_database(e)
        if reason is None or "not a database" in reason:
            return  # no SQLite file at all, locked, unreadable, ...: the storage's own one-line error says it
        raise ConfigError(damaged_storage_message(storage_url, reason)) from None
    if found is None:
        raise ConfigError(f"{path} is not an Optuna study database (no 'studies' table); give the study.db that "
                          "`ermrl evolve` wrote (`storage_url`), or run `ermrl evolve` to create the study",
                          owner=load_study)
    if check and check[0] != "ok":  # e.g. "Page 3: btreeInitPage() returns error code 11"
        raise ConfigError(damaged_storage_message(storage_url, "database disk image is malformed"))


def _current(record: dict) -> dict:
    """A stored record as this version writes it: decoded (fields added since it was written take their
    defaults) and encoded again, so that a study started before a config field existed still resumes."""
    from ermrl.evolution.record import decode_study_record, encode_study_record

    return encode_study_record(decode_study_record(record))


def _comparable(record: dict) -> str:
    """The config without the fields that may change between a run and its resumption: the trial target, the
    baselines (a resumed study keeps the constants it started with) and the env workers, threads and training
    processes (results do not depend on them). A worker's own settings (``worker_config.WorkerConfig``: batch, index,
    heartbeats) are not in the record at all."""
    keep = {k: v for k, v in record.items() if k not in ("trials", "baselines")}
    if isinstance(keep.get("train"), dict):
        keep["train"] = {k: v for k, v in keep["train"].items() if k not in ("env_workers", "env_threads", "processes")}
    return json.dumps(keep, sort_keys=True, default=str)


def copy_trials(study: optuna.Study, trials: list, url: str) -> optuna.Study:
    """A new study named as ``study`` in ``url`` with ``study``'s ermrl record and software versions and ``trials``
    (FrozenTrials: their params, values, states and attributes, the CMA-ES optimizers Optuna stored included), so
    that ``ermrl select`` and ``ermrl test`` run on it as on the original. ``url`` must not hold that study."""
    copy = optuna.create_study(storage=make_storage(url, heartbeat=None), study_name=study.study_name,
                               direction="maximize")
    for key in (ATTR, "software"):
        if key in study.user_attrs:
            copy.set_user_attr(key, study.user_attrs[key])
    copy.add_trials(trials)
    return copy

