"""``ermrl dashboard``: serves optuna-dashboard (the ``dashboard`` extra) for one study on a local port.

The study is found as ``ermrl report`` finds it (``runs/STUDY/study.db``, or ``--out``, or ``--storage`` with any
URL ermrl reads: SQLite, a journal file, PostgreSQL). Everything that can go wrong (no optuna-dashboard, no
storage file, no such study, a port in use) is a one-line error before the server starts."""

from __future__ import annotations

import errno
import importlib.util
from pathlib import Path

from ermrl.errors import ConfigError


def add_parser(sub, formatter) -> None:
    from ermrl.cli import options
    from ermrl.cli.common import study_location

    p = sub.add_parser("dashboard", help="serve optuna-dashboard: a live view of a study in the browser",
                       description="Serve optuna-dashboard for a study's storage on HOST:PORT and print the study "
                                   "page's URL. It shows every trial (state, fitness, Φ, the user attributes "
                                   "generation, seed_fitness, failure, ...), the fitness over trials, parallel "
                                   "coordinates, slices, contours, ranks and Φ importances, and refreshes while a "
                                   "study runs. Ctrl-C stops it.", formatter_class=formatter)
    study_location(p)
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (127.0.0.1: this machine only; the dashboard can edit the storage)")
    p.add_argument("--port", type=int, default=8080, help="port to listen on; 0 picks a free one")
    options.add_config_option(p)


def run_command(args) -> int:
    from ermrl.cli.common import check_study_name
    from ermrl.evolution.study import default_storage, load_study, make_storage, shown_url

    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port {args.port} is not a port; give 1..65535, or 0 for any free port")
    if importlib.util.find_spec("optuna_dashboard") is None:
        raise ConfigError("optuna-dashboard is not installed; install it with pip install 'ermrl[dashboard]'")
    check_study_name(args.study)
    url = args.storage or default_storage(args.out or Path("runs") / args.study)
    load_study(url, args.study)  # one-line errors; never creates a storage file just to look
    import optuna_dashboard  # after the cheap checks: it imports scikit-learn (seconds)

    storage = make_storage(url)
    app = optuna_dashboard.wsgi(storage)
    server = _listen(app, args.host, args.port)
    host, port = server.server_address[:2]
    host = f"[{host}]" if ":" in host else host
    study_id = storage.get_study_id_from_name(args.study)
    print(f"optuna-dashboard for study {args.study!r} in {shown_url(url)}", flush=True)
    print(f"open http://{host}:{port}/dashboard/studies/{study_id} (Ctrl-C stops it)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("dashboard stopped")
    finally:
        server.server_close()
    return 0


def _listen(app, host: str, port: int):
    """A threaded wsgiref server for ``app`` bound to ``host:port`` (what optuna-dashboard's own CLI runs),
    without a log line per request (the page polls every few seconds)."""
    import socket
    from socketserver import ThreadingMixIn
    from wsgiref.simple_server import WSGIRequestHandler, WSGIServer, make_server

    class Server(ThreadingMixIn, WSGIServer):
        daemon_threads = True

    class QuietHandler(WSGIRequestHandler):
        def log_message(self, format, *args):
            pass

    if ":" in host:
        Server.address_family = socket.AF_INET6
    try:
        return make_server(host, port, app, server_class=Server, handler_class=QuietHandler)
    except OSError as e:
        if e.errno == errno.EADDRINUSE:
            raise ConfigError(f"port {port} on {host} is in use; pass another --port, or --port 0 for any free "
                              "port") from None
        raise ConfigError(f"cannot listen on {host}:{port} ({e.strerror or e}); pass --host 127.0.0.1 or another "
                          "--port") from None
