"""Crash-safe writing: a file is written whole or not at all (:func:`atomic_path`), a folder of results appears
complete or not at all (:func:`staged_folder`), a journal file's torn last line is cut (:func:`repair_journal`),
and an output path is checked before any work (:func:`check_folder`, :func:`check_file`). The file formats that
use them live in :mod:`ermrl.storage`, which re-exports these. docs/reliability.md has the faults tried.
"""

from __future__ import annotations

import contextlib
import errno
import glob
import json
import os
import re
import shutil
import socket
import sys
import tempfile
import time
from pathlib import Path

from ermrl.errors import ConfigError


@contextlib.contextmanager
def atomic_path(path: Path | str):
    """Yields a temporary path beside ``path``; renames it over ``path`` when the block ends without error."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    try:  # from here on, whatever stops the block (an error, SIGTERM as SystemExit) removes the temporary file
        os.close(fd)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; the final file gets the usual permissions
        yield Path(tmp)
        _fsync(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _fsync(path: str) -> None:
    """Flushes a closed file's data to disk, so that the rename never publishes an empty file after a power cut."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def staged_folder(folder: Path | str, marker: str = "summary.json", stale: str | None = None):
    """Yields a hidden sibling folder, ``.NAME.partial-HOST-PID``, to write ``folder``'s files into; when the block
    ends without error they take ``folder``'s place, so that a crash (even kill -9) leaves ``folder`` as it was or
    complete, never half-written.

    A missing or empty ``folder`` is replaced by renaming the staged folder (one atomic step). Into an existing
    one, ``marker`` (the file readers take to mean "complete") is removed first, then every staged file is renamed
    over its namesake, ``marker`` last. Files the stage lacks are kept, except those whose path relative to
    ``folder`` fully matches the regular expression ``stale`` (files of the same writer's earlier run, such as old
    agents): nothing that the writer never writes is removed. A staging folder left by a killed process is removed
    by the next writer of ``folder`` on the same host."""
    folder = Path(os.path.realpath(folder))
    folder.parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{folder.name}.partial-{socket.gethostname()}-"
    for old in folder.parent.glob(glob.escape(prefix) + "*"):
        pid = old.name.removeprefix(prefix)
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(old, ignore_errors=True)
    stage = folder.parent / f"{prefix}{os.getpid()}"
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    try:
        yield stage
        _publish(stage, folder, marker, stale)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def _publish(stage: Path, folder: Path, marker: str, stale: str | None) -> None:
    """Moves ``stage``'s files into ``folder`` (see :func:`staged_folder`)."""
    try:
        os.rename(stage, folder)  # replaces a missing or empty folder
        return
    except OSError as e:
        if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
            raise
    files = sorted((p.relative_to(stage) for p in stage.rglob("*") if not p.is_dir()), key=lambda p: p == Path(marker))
    with contextlib.suppress(FileNotFoundError):
        (folder / marker).unlink()
    if stale is not None:
        for old in folder.rglob("*"):
            path = old.relative_to(folder)
            if re.fullmatch(stale, path.as_posix()) and not old.is_dir() and not (stage / path).exists():
                old.unlink()
    for p in files:
        (folder / p).parent.mkdir(parents=True, exist_ok=True)
        os.replace(stage / p, folder / p)


def repair_journal(path: Path | str) -> int:
    """Cuts a torn last line from the Optuna journal file ``path``: one without its newline, which a writer that
    died mid-append (or a full disk) leaves. Optuna reads past it, but its next append would glue onto it and
    make the whole journal unreadable. Done under the journal's own lock, so a live writer is never cut short,
    and only after a whole line that is a journal record, so that a file that is no journal is never touched.
    Returns the number of bytes cut (0 for a sound, missing or foreign file)."""
    path = Path(path)
    if not _torn(path):
        return 0
    lock = journal_lock(path)  # what the journal storage appends under (evolution.study.make_storage)
    lock.acquire()
    try:
        if not _torn(path):
            return 0
        size = path.stat().st_size
        with open(path, "rb") as f:
            end = _after_last_newline(f, size)  # where the torn line starts
            if end == 0:
                return 0
            start = _after_last_newline(f, end - 1)  # the last whole line is [start, end)
            f.seek(start)
            last = f.read(end - start)
        try:
            record = json.loads(last)
        except ValueError:
            record = None
        if not (isinstance(record, dict) and "op_code" in record):
            return 0  # not a journal (or its first record is torn): left as it is
        os.truncate(path, end)
        return size - end
    finally:
        lock.release()


JOURNAL_LOCK_GRACE_S = 30
"""A journal lock held this long is stale and broken: Optuna's own rule (its ``grace_period``). A writer holds it
for one append, milliseconds."""


def journal_lock(path: Path | str, grace_period: float = JOURNAL_LOCK_GRACE_S):
    """The lock that every ermrl process writes the Optuna journal file ``path`` under: Optuna's symlink lock
    (the link ``PATH.lock``, so that ermrl and plain Optuna exclude each other) on the absolute path, whose wait
    never spins and always breaks a stale lock (:class:`_JournalLock`)."""
    from optuna.storages.journal import JournalFileSymlinkLock

    class _JournalLock(JournalFileSymlinkLock):
        """Optuna's wait (5.0) reads the lock's age through the link, so a link left dangling by a process that
        died holding it (a relative path: ``d/j.log.lock -> d/j.log`` points to ``d/d/j.log``) has no age: it
        retries at once, forever, at 100% CPU. This one reads the link itself (``lstat``): a lock is stale once
        the same link has stood for ``grace_period`` seconds, seen by this process or by its time stamp, and
        is then broken (with a note on stderr). It sleeps between tries, and never removes a lock it does not
        hold when stopped while waiting."""

        def acquire(self) -> bool:
            seen, since, delay = None, time.monotonic(), 0.001
            while True:
                try:
                    os.symlink(self._lock_target_file, self._lock_file)
                    return True
                except FileExistsError:
                    pass
                try:
                    st = os.lstat(self._lock_file)
                except FileNotFoundError:
                    continue  # released meanwhile: try again at once
                stamp = (st.st_ino, st.st_mtime_ns)
                now = time.monotonic()
                if stamp != seen:
                    seen, since = stamp, now
                if max(now - since, time.time() - st.st_mtime) > self.grace_period:
                    self._break(st.st_ino)
                    delay = 0.001
                    continue
                time.sleep(delay)
                delay = min(2 * delay, 0.25)

        def _break(self, inode: int) -> None:
            """Removes the stale lock link ``inode``; a link another process made meanwhile is put back."""
            aside = f"{self._lock_file}.stale-{os.getpid()}"
            try:
                os.rename(self._lock_file, aside)
            except FileNotFoundError:
                return
            if os.lstat(aside).st_ino != inode:  # another waiter broke it first and now holds a new one
                with contextlib.suppress(FileExistsError):
                    os.link(aside, self._lock_file, follow_symlinks=False)
            else:
                print(f"note: removed the stale lock {self._lock_file} (held for over {self.grace_period:g} s: "
                      "a process stopped while writing the journal)", file=sys.stderr)
            os.unlink(aside)

    return _JournalLock(os.path.abspath(path), grace_period)


def _after_last_newline(f, end: int) -> int:
    """The offset just after the last newline before offset ``end`` of the binary file ``f`` (0: none)."""
    while end > 0:
        start = max(0, end - 65536)
        f.seek(start)
        nl = f.read(end - start).rfind(b"\n")
        if nl >= 0:
            return start + nl + 1
        end = start
    return 0


def _torn(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            if f.tell() == 0:
                return False
            f.seek(-1, os.SEEK_END)
            return f.read(1) != b"\n"
    except FileNotFoundError:
        return False


def check_folder(path: Path | str, flag: str = "`out`") -> Path:
    """``path`` if a folder is or can be made there: it is a folder, or its nearest existing parent is a writable
    folder. Otherwise ConfigError (one line, naming ``flag``: the parameter that gave ``path``, in backquotes as
    :class:`~ermrl.errors.ConfigError` names one, or a flag), so that a bad output path fails before any training
    instead of losing the results at the end."""
    path = Path(path)
    for p in (path, *path.parents):
        if not p.exists():
            continue
        if not p.is_dir():
            where = f"{flag} {p}" if p == path else f"{flag} {path}: its parent {p}"
            raise ConfigError(f"{where} is a file, not a folder; give a folder path (it is created if missing)")
        if (reason := cannot_write(p)) is not None:
            raise ConfigError(f"{flag} {path}: cannot write in {p} ({reason}); give a folder you can write")
        return path
    return path


def cannot_write(folder: Path) -> str | None:
    """Why nothing can be created in ``folder``, else None. Tried for real (an empty folder made and removed):
    permission bits do not bind root, and a read-only mount or a pseudo file system refuses anyone."""
    made = None
    try:
        made = tempfile.mkdtemp(prefix=".ermrl-check-", dir=folder)
    except OSError as e:
        reason = e.strerror or type(e).__name__
        return reason[0].lower() + reason[1:]
    finally:  # also when SIGTERM (SystemExit) comes in between
        if made is not None:
            os.rmdir(made)
    return None


def check_file(path: Path | str, flag: str = "`out`", example: str = "NAME.png") -> Path:
    """``path`` if a file can be written there: it is not a folder, and its nearest existing parent is a writable
    folder. Otherwise ConfigError (one line, naming ``flag`` as :func:`check_folder` does; a folder gets the hint
    ``path/example``), before any work."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{flag} {path} is a folder; give a file path such as {path / example}")
    for p in path.parents:
        if not p.exists():
            continue
        if not p.is_dir():
            raise ConfigError(f"{flag} {path}: its parent {p} is a file, not a folder; give a path in a folder")
        if (reason := cannot_write(p)) is not None:
            raise ConfigError(f"{flag} {path}: cannot write in {p} ({reason}); give a folder you can write")
        break
    return path
