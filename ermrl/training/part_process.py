"""The main of a helper process of :mod:`ermrl.training.processes`: trains one part of a population.

Started as ``python -c "from ermrl.training.part_process import serve; serve(FD)"`` with one end of a socket pair;
it ignores Ctrl-C (which reaches the whole process group: its parent stops it) and ends once its parent is gone.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from multiprocessing.connection import Connection

from ermrl.training.trainer import Trainer

PARENT_POLL_S = 0.5
"""Seconds between a helper's looks at whether its parent is still alive."""


def _exit_with_parent(parent: int) -> None:
    """Ends this process once its parent is gone (then it is adopted: the parent pid changes)."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def serve(fd: int) -> None:
    """A helper's main: trains the part sent on socket ``fd`` and sends back ("ok", Results), or ("error", line);
    ("log", line) messages come first."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()
    conn = Connection(fd)
    config, population, snapshot, snapshot_every_s = conn.recv()
    try:
        results = Trainer(config).run(population, snapshot=snapshot, snapshot_every_s=snapshot_every_s,
                                      log=lambda line: conn.send(("log", line)))
    except Exception as error:  # reported to the parent, which raises it
        conn.send(("error", f"{type(error).__name__}: {error}"))
        return
    conn.send(("ok", results))
