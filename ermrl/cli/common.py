"""What the commands share: the study options (--study, --storage, --out), where a study's folder and storage
are, progress bars for commands that train several models in turn, the note under a time estimate when the
machine looks busy, and the one-line message of a file that cannot be read."""

from __future__ import annotations

from pathlib import Path

from ermrl.cli import options
from ermrl.errors import ConfigError


def config_and_quiet(p, quiet: bool = True) -> None:
    """Adds --config and, with ``quiet``, --quiet."""
    options.add_config_option(p)
    if quiet:
        p.add_argument("--quiet", action="store_true", help="no progress display")


def study_location(p, required: bool = True) -> None:
    """Adds --study, --storage and --out: the study's name (``name`` of the study functions) and where it is
    (their ``storage_url``: --storage, else the sqlite file in the --out folder)."""
    from ermrl.evolution import study

    options.sets(p.add_argument("--study", required=required, default=None,
                                help="study name, as given to or printed by `ermrl evolve`" + (
                                    "" if required else " (default ENV-Kres-STEPSk)")),
                 "name", study.load_study, study.check_resumable, study.open_study)
    options.sets(p.add_argument("--storage", type=options.storage, default=None,
                                help="Optuna storage URL or journal file (default sqlite in runs/STUDY)"),
                 "storage_url")
    options.sets(p.add_argument("--out", type=options.path, default=None, help="run folder (default runs/STUDY)"),
                 "storage_url")


STUDY_NAME_MAX = 100
"""The longest study name: it names the study's folder (runs/NAME), whose files add their own names to it."""


def check_study_name(name: str | None, flag: str = "--study") -> None:
    """A study name is one folder name under runs/: not empty, no path separator, not '.' or '..', no control
    characters, at most :data:`STUDY_NAME_MAX` characters; else ConfigError, so that no study is written outside
    runs/ (``--study ../../x``, an absolute path) or fails on an over-long file name."""
    if name is None:
        return
    if not name.strip():
        raise ConfigError(f"{flag} is empty; give the study's name (e.g. cartpole-1res), or leave {flag} out "
                          "for `ermrl evolve` to name it")
    bad = next((c for c in name if c in "/\\" or not c.isprintable()), None)
    if bad is not None or name.strip(".") == "":
        what = f"it holds {bad!r}" if bad is not None else "it is only dots"
        raise ConfigError(f"{flag} {name!r} is not a plain name ({what}); a study's files go in runs/NAME, so give "
                          "a name without / or \\ (e.g. cartpole-1res), and --out or --storage to put them elsewhere")
    if len(name) > STUDY_NAME_MAX:
        raise ConfigError(f"{flag} is {len(name)} characters long; give a name of at most {STUDY_NAME_MAX}")


def run_dir(args) -> Path:
    """The study's folder (--out, else runs/STUDY), checked to be a folder that can be written."""
    from ermrl import storage

    check_study_name(args.study)
    return storage.check_folder(args.out or Path("runs") / args.study)


def storage_url(args) -> str:
    """The study's storage: --storage, else the SQLite file in its folder."""
    from ermrl.evolution.study import default_storage

    check_study_name(args.study)
    return args.storage or default_storage(run_dir(args))


def storage_flag(args) -> str:
    """The --storage and --out flags to repeat in a suggested next command."""
    from ermrl.evolution.study import shown_url

    out = f" --storage {shown_url(args.storage)}" if args.storage else ""
    return out + (f" --out {args.out}" if args.out else "")


def bars(quiet: bool):
    """(progress factory label -> progress_fn, closer) for commands that train several models in turn."""
    from ermrl.cli.progress import TrainingBar

    bars = []

    def progress(label):
        bar = TrainingBar(label, enabled=not quiet)
        bar.__enter__()
        bars.append(bar)
        return bar.update

    def close():
        for bar in bars:
            bar.__exit__(None, None, None)

    return progress, close


BUSY_LOAD_PER_CORE = 0.75
"""A 1-minute load average above this many runnable processes per core means another job holds the cores."""


def busy_note(load: float | None = None, cores: int | None = None) -> str | None:
    """A note to print under a time estimate when the machine looks busy, else None. ``load``: the 1-minute load
    average (default: the system's); ``cores``: the CPUs this process may use (default: its affinity).

    The estimates assume free cores. Beside another training they are several times too short: a host-env run's
    main process and env workers hand over at every step, and on 2 cores it ran ≈ 4× slower beside another job
    (docs/benchmarks.md, "Host backend: Ant-v5")."""
    import os

    if load is None:
        try:
            load = os.getloadavg()[0]
        except OSError:  # not available on this platform
            return None
    cores = cores or (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
    if load <= BUSY_LOAD_PER_CORE * cores:
        return None
    return (f"note: the machine looks busy (load average {load:.1f} on {cores} cores); the estimate assumes free "
            "cores, and training beside another job can take several times longer")


def check_memory(train_config, agents: int, what: str) -> None:
    """:func:`ermrl.training.memory.check` of ``agents`` agents trained with ``train_config`` on its env."""
    from ermrl import envs
    from ermrl.training import memory

    info = envs.describe(train_config.env_id, train_config.backend)
    memory.check(train_config, agents, info.obs_dim, info.action.feature_dim, what)


def own_snapshot(path: Path) -> Path:
    """``path`` if it is free or holds a training snapshot (which the run may resume from, then replaces and
    removes); ConfigError before any work when something else is there, so that it is never overwritten."""
    from ermrl.training import snapshots

    if path.is_dir() or path.exists() and not snapshots.is_snapshot(path):
        raise ConfigError(f"{path} is in the way: the run keeps its snapshot there, and it is not one (or is "
                          "damaged); move it away or give another --out")
    return path


def one_line(e: OSError | ValueError) -> str:
    """An OSError or ValueError of a file read as one line: "No such file or directory: PATH" for a missing one."""
    if isinstance(e, OSError) and e.strerror and e.filename:
        return f"{e.strerror}: {e.filename}"
    return str(e).strip().splitlines()[0]
