"""Optuna's RDB storage (SQLite, PostgreSQL, MySQL) as ermrl opens it: the driver, the engine options, and calls
that survive a worker standing still inside a transaction (docs/scaling.md, "Heartbeats").

A worker that stops in the middle of a storage transaction (SIGSTOP, a suspended laptop, a machine cut off)
holds that transaction's row locks; another worker failing its trials would wait on them until the server
notices the connection dead, hours later. So on PostgreSQL a session left idle inside a transaction for the
heartbeat grace period is ended by the server (``idle_in_transaction_session_timeout``): the locks go, nothing
of that transaction is committed, and the others fail the trials as lost. When the stopped worker runs again,
the call it was in fails with its connection gone; ``RDBStorage`` runs that call again once, on a new connection
(``pool_pre_ping`` replaces the ended one), and the worker goes on as one that stood still between two calls:
it finds its trials failed and drops their results.
"""

from __future__ import annotations

import functools
import importlib.util
import random
import time
import warnings

import optuna
from optuna.exceptions import StorageInternalError

from ermrl.evolution.heartbeat import GRACE_PERIOD_S

SCHEMA_RETRIES = 5
SESSION_ENDED = "25P03"
"""PostgreSQL's SQLSTATE for a session ended by ``idle_in_transaction_session_timeout``."""
RETRIED = ("create_new_study", "delete_study", "set_study_user_attr", "set_study_system_attr",
           "get_study_id_from_name", "get_study_name_from_id", "get_study_directions", "get_study_user_attrs",
           "get_study_system_attrs", "get_all_studies", "_create_new_trial", "_set_trial_param", "get_trial_param",
           "set_trial_state_values", "set_trial_intermediate_value", "set_trial_user_attr", "set_trial_system_attr",
           "get_trial_id_from_study_id_trial_number", "get_trial", "get_all_trials", "_get_trials",
           "_get_best_trial_id", "record_heartbeat", "_get_stale_trial_ids")
"""The storage calls that read or write the database (each one transaction, or none committed)."""


def session_ended(error: BaseException) -> bool:
    """Whether ``error`` (a storage call's) says that the call's connection is gone: the server ended the session
    for standing idle inside a transaction (SQLSTATE 25P03, or, when the process did not read that message before
    the socket closed, a connection "closed unexpectedly" that SQLAlchemy invalidated). The call may run again: an
    ended session committed nothing. (A connection lost in the middle of a COMMIT for another reason might have
    committed; running the call again is then harmless for the calls a worker makes: an attribute is written
    twice, a tell or fail finds its trial finished and says so, a trial created twice leaves one without worker
    that is failed after the grace period.) The connection's error may lie deeper in the chain: Optuna's
    ``_get_trials`` catches it and tries again on the same session, which then fails with "Can't reconnect until
    invalid transaction is rolled back"."""
    if not isinstance(error, StorageInternalError):
        return False
    seen, cause = set(), error.__cause__
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if getattr(cause, "connection_invalidated", False) \
                or getattr(getattr(cause, "orig", None), "sqlstate", None) == SESSION_ENDED:
            return True
        cause = cause.__cause__ or cause.__context__
    return False


def _once_more_after_an_ended_session(method):
    @functools.wraps(method)
    def call(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except StorageInternalError as e:
            if not session_ended(e):
                raise
            return method(self, *args, **kwargs)
    return call


class RDBStorage(optuna.storages.RDBStorage):
    """Optuna's RDB storage whose calls run again once when the server ended their session (module docstring)."""


for _name in RETRIED:
    setattr(RDBStorage, _name, _once_more_after_an_ended_session(getattr(optuna.storages.RDBStorage, _name)))


def rdb_storage(url: str, heartbeat: tuple[int, int] | None) -> RDBStorage:
    """The RDB storage for ``url``, with Optuna's heartbeats (interval, grace period in seconds) where given;
    retried when workers started at once race to create the schema of a new database (the losers' CREATE TABLE
    or CREATE TYPE fails with a duplicate)."""
    import sqlalchemy.exc

    kwargs = {} if heartbeat is None else {"heartbeat_interval": heartbeat[0], "grace_period": heartbeat[1]}
    engine_kwargs = _engine_kwargs(url, GRACE_PERIOD_S if heartbeat is None else heartbeat[1])
    for attempt in range(SCHEMA_RETRIES):
        try:
            with warnings.catch_warnings():  # heartbeat_interval is an ExperimentalWarning in Optuna
                warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                return RDBStorage(_driver_url(url), engine_kwargs=engine_kwargs, **kwargs)
        except (sqlalchemy.exc.IntegrityError, sqlalchemy.exc.ProgrammingError):
            if attempt == SCHEMA_RETRIES - 1:
                raise
            time.sleep(0.2 + random.random())


def _postgres(url: str) -> bool:
    scheme, sep, _ = url.partition("://")
    return bool(sep) and scheme in ("postgresql", "postgres", "postgresql+psycopg")


def driver_missing(url: str) -> bool:
    """Whether ``url`` names PostgreSQL and its driver, psycopg (the ``workers`` extra), is not installed."""
    return _postgres(url) and importlib.util.find_spec("psycopg") is None


def _driver_url(url: str) -> str:
    """``url`` with PostgreSQL's driver named: SQLAlchemy's default for ``postgresql://`` is psycopg2, which the
    ``workers`` extra does not install; psycopg (3) is the one it installs."""
    return f"postgresql+psycopg://{url.partition('://')[2]}" if _postgres(url) else url


def _engine_kwargs(url: str, grace_s: int) -> dict:
    """SQLAlchemy engine options: a connect timeout on database servers; on PostgreSQL, sessions ended after
    ``grace_s`` seconds idle inside a transaction, and ended connections replaced (module docstring)."""
    if url.startswith("postgres"):
        return {"connect_args": {"connect_timeout": 5,
                                 "options": f"-c idle_in_transaction_session_timeout={1000 * grace_s}"},
                "pool_pre_ping": True}
    if url.startswith("mysql"):
        return {"connect_args": {"connect_timeout": 5}}
    return {}
