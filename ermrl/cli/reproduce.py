"""``ermrl reproduce [STEP|CLAIM ...]``: the runs behind docs/paper.md, step by step (the steps are data, in
:mod:`ermrl.experiments.reproduction`); ``--list`` names them, ``--dry-run`` prints their commands."""

from __future__ import annotations

from pathlib import Path

from ermrl.cli import options
from ermrl.errors import ConfigError


def add_parser(sub, formatter) -> None:
    p = sub.add_parser("reproduce", help="run the paper's reproduction steps (by step name or claim), resumably",
                       description="Run the steps behind docs/paper.md in order, from the repository's root: each "
                                   "step's studies go to journals under docs/data/ (committed), its test phases to "
                                   "runs/experiments/, and their small files are copied beside the journal. Every "
                                   "command resumes where it stopped, so run it again after any stop. Name steps "
                                   "(h2_converged) or claims (C7: every step that serves it); none runs them all.",
                       formatter_class=formatter)
    p.add_argument("names", nargs="*", metavar="STEP|CLAIM", help="step names or claims C1..C17 (default: every step)")
    p.add_argument("--list", action="store_true", help="print the steps (those named, else all): name, claims, "
                                                       "description; run nothing")
    p.add_argument("--dry-run", action="store_true", help="print the commands the steps would run, as shell lines; "
                                                          "run nothing")
    p.add_argument("--root", type=options.path, default=None, metavar="DIR",
                   help="the repository's root, where docs/data/ is (default: the checkout of this ermrl, else the "
                        "current folder)")
    options.add_options(p, "stop")
    options.add_config_option(p)


def _root(given: Path | None) -> Path:
    """The repository's root: ``given``, else the checkout this package is in, else the current folder; ConfigError
    unless it has docs/data/."""
    import ermrl

    checkout = Path(ermrl.__file__).resolve().parents[1]
    root = given or next((r for r in (checkout, Path.cwd()) if (r / "docs" / "data").is_dir()), Path.cwd())
    if not (root / "docs" / "data").is_dir():
        raise ConfigError(f"{root} is not the repository's root (it has no docs/data/); run from a checkout of "
                          "ermrl, or give --root")
    return root


def cmd_reproduce(args) -> int:
    import time

    from ermrl.experiments.reproduction import catalog, execute

    stop_at = None if args.stop_after is None else time.time() + args.stop_after  # from the command's start
    steps = catalog.select(args.names)
    if args.list:
        width = max(len(s.name) for s in steps)
        for s in steps:
            print(f"{s.name:<{width}}  {','.join(s.claims) or '-':<10} {s.description}")
        return 0
    if args.dry_run:
        for s in steps:
            execute.dry_run(s)
        return 0
    root = _root(args.root)
    for s in steps:
        execute.run_step(s, root, stop_at=stop_at)
    return 0
