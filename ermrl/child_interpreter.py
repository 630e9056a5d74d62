"""A fresh Python interpreter that serves this process over a socket pair.

The env workers (:mod:`ermrl.envs.host_groups`) and the training helpers (:mod:`ermrl.training.processes`) run in
fresh interpreters (``python -c "from MODULE import serve; serve(FD)"``), not in multiprocessing children: fork is
unsafe under JAX's threads, and spawn would re-run the user's main script. Messages are pickled Python objects; a
child answers ``(status, value)`` pairs, and ``("error", "Type: message")`` when what it was asked failed.
"""

from __future__ import annotations

import socket
import subprocess
import sys
from multiprocessing.connection import Connection

from ermrl.errors import RunFailed


class ChildDied(RunFailed):
    """The child interpreter closed its end before answering: it crashed or was killed (the out-of-memory
    killer, ``kill -9``). A run that snapshots resumes from its last snapshot when rerun."""


class ChildInterpreter:
    """``python -c "from {module} import serve; serve(FD)"`` with ``FD`` one end of a socket pair; ``what`` names
    the child in errors ("an env worker process")."""

    def __init__(self, module: str, what: str):
        self.what = what
        parent, child = socket.socketpair()
        code = f"from {module} import serve; serve({child.fileno()})"
        self.process = subprocess.Popen([sys.executable, "-c", code], pass_fds=[child.fileno()])
        child.close()
        self.conn = Connection(parent.detach())

    def send(self, message) -> None:
        self.conn.send(message)

    def ready(self) -> bool:
        """True when an answer (or the child's end) waits to be received."""
        return self.conn.poll()

    def receive(self):
        """The next ``(status, value)`` the child sent. :class:`ChildDied` when it is gone."""
        try:
            return self.conn.recv()
        except (EOFError, ConnectionResetError):
            code = self.process.wait(timeout=5)
            raise ChildDied(f"{self.what} died (exit code {code}); see its error above") from None

    def close(self, message=None, wait_s: float = 5.0) -> None:
        """Sends ``message`` (a polite stop) when given, waits ``wait_s`` for the child to end, kills it if it
        has not, and closes the socket."""
        if message is not None and self.process.poll() is None:
            try:
                self.conn.send(message)
            except (BrokenPipeError, OSError):
                pass
        try:
            self.process.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=10)
        self.conn.close()
