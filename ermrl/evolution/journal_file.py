"""The Optuna journal file as ermrl's storages open it (:func:`ermrl.evolution.study.make_storage`): Optuna's
``JournalFileBackend``, appended under :func:`ermrl.atomic.journal_lock`, that checks before each read, and under
the lock just before each append, that the part of the file it has already read is still there.

Optuna reads a journal incrementally: it remembers the byte offset where its last read ended, and reads on from
there. A journal only grows, but one kept in a git checkout (``docs/data/``) can be rewritten under a running
study by ``git stash``, ``git checkout`` or ``git pull``, or by a copy over it. Optuna then reads on from an
offset that no longer ends a record it has seen: it silently reads nothing while the file is shorter (so the run
stops seeing its own writes), then fails on half a record, or replays another copy's records as its own; and it
appends its records to the wrong copy. :class:`CheckedJournalFile` keeps the last bytes before that offset and
compares them first: on a difference it raises :class:`JournalChanged` (one line, exit status 1), and writes
nothing. Other writers only append after that offset, and :func:`ermrl.atomic.repair_journal` only cuts a torn
last line, which Optuna never counts as read, so neither trips it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Generator

from optuna.storages.journal import JournalFileBackend, JournalFileSymlinkLock

from ermrl.errors import RunFailed

TAIL_BYTES = 256
"""How many bytes before the read offset are kept and compared (the last record or two of the journal)."""


class JournalChanged(RunFailed):
    """The journal file was rewritten under a run that uses it (see the module's docstring). The message says
    how to go on; nothing was written to the file by the operation that found it."""


class CheckedJournalFile(JournalFileBackend):
    """Optuna's journal file backend for ``path``, written under ``lock_obj`` (:func:`ermrl.atomic.journal_lock`,
    or Optuna's default), that raises :class:`JournalChanged` instead of reading or appending once the bytes it
    has read were changed."""

    def __init__(self, path: str, lock_obj: JournalFileSymlinkLock | None = None) -> None:
        super().__init__(path, lock_obj=lock_obj)
        self._path = Path(path)
        self._read_to = 0
        """The byte offset where the last whole record read ends."""
        self._tail = b""
        """The file's bytes ``[_read_to - len(_tail), _read_to)`` as they were read."""

    def read_logs(self, log_number_from: int) -> Generator[dict[str, Any], None, None]:
        self._check()
        yield from super().read_logs(log_number_from)
        self._remember()

    def append_logs(self, logs: list[dict[str, Any]]) -> None:
        """Optuna's append (one write of the records as JSON lines, fsynced, under the lock), with the check made
        under the lock too, just before the write: a rewrite can then slip in only between the two, microseconds,
        not while the append waits for the lock (up to a quarter of a second, under contention)."""
        data = "".join(json.dumps(log, separators=(",", ":")) + "\n" for log in logs).encode("utf-8")
        self._lock.acquire()
        try:
            self._check()
            with open(self._path, "ab") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
        finally:
            self._lock.release()

    def _remember(self) -> None:
        """Keeps the end of what has been read: the offset after the last whole record and the bytes before it."""
        end = max(self._log_number_offset.values(), default=0)
        if end == self._read_to:
            return
        with open(self._path, "rb") as f:
            f.seek(max(end - TAIL_BYTES, 0))
            self._tail = f.read(end - max(end - TAIL_BYTES, 0))
        self._read_to = end

    def _check(self) -> None:
        if not self._read_to:
            return
        try:
            with open(self._path, "rb") as f:
                size = os.fstat(f.fileno()).st_size
                f.seek(self._read_to - len(self._tail))
                tail = f.read(len(self._tail))
        except FileNotFoundError:
            size, tail = 0, b""
        if tail != self._tail:
            now = "is gone" if not self._path.exists() else (
                f"is now {size:,} bytes" if size < self._read_to else "changed there")
            raise JournalChanged(
                f"the journal {self._path} was rewritten while this run used it: it had read its first "
                f"{self._read_to:,} bytes, and the file {now} (a git checkout, stash or pull, or a copy over it?); "
                "stop every run on it, put back the copy they wrote to, and rerun to continue")
