"""What a reproduction step is made of: commands and the file moves between them, as plain data.

A :class:`Step` is a name, the paper's claims it serves (``C1`` .. ``C17``), a one-line description and a tuple of
actions, run in order from the repository's root by :mod:`ermrl.experiments.reproduction.execute`:

- :class:`Run`: one command (``ermrl ARGS``, a ``paper/`` script run by this interpreter, or a script run by the
  reference pipeline's interpreter), skipped when all of its ``skip_if`` conditions hold (a run's summary.json
  exists: it is done), its output optionally also written to a file (``tee``);
- :class:`Experiment`: ``ermrl experiment run NAME --scale SCALE`` with its journal under ``docs/data/NAME-SCALE/``,
  its test phases' small files put back before and copied there after (:mod:`.folders`);
- :class:`Collect`, :class:`CopyFiles`, :class:`Remove`, :class:`MakeDirs`: file moves;
- :class:`StopIf`: ends the step (not the command) with a message when its conditions hold.

A command's arguments are strings, or values known only when it runs: :class:`PhiFlags` (a study's Φ* as
``--sr .. --leak-rate .. --iss ..``, read from its journal after the evolution and selection before it) and
:class:`FirstOf` (the first of several paths that exists). Every path is relative to the repository's root.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path

STORE = "docs/data/baseline-models"
"""The PPO baselines trained once and shared by the test phases that have the same (``--baseline-store``)."""
TEST10 = ("--test-seeds", "10", "--test-timesteps", "1000000")
"""An experiment's test phases at 10 seeds × 1M steps."""
NOT_SAVED = ("--no-save-agents", "--quiet")
"""An ``ermrl train`` run whose agents are not kept, without progress display."""
DEFAULT_PHI = ("--sr", "0.95", "--leak-rate", "0.5", "--iss", "1.0")
"""The default Φ (ReservoirPy's sr and leak rate, input scaling 1) as ``ermrl train`` flags."""
TEST_FILES = ("summary.json", "summary.csv", "curves.csv", "test_config.json", "test_phase.png")
"""The small files of a test phase that a step copies beside its journal (not its saved agents)."""


# -- conditions ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Exists:
    """Holds when ``path`` (a file or a folder) exists."""
    path: str

    def holds(self, root: Path) -> bool:
        return (root / self.path).exists()

    def shell(self) -> str:
        return f"[ -e {shlex.quote(self.path)} ]"


@dataclass(frozen=True)
class Missing:
    """Holds when ``path`` does not exist."""
    path: str

    def holds(self, root: Path) -> bool:
        return not (root / self.path).exists()

    def shell(self) -> str:
        return f"[ ! -e {shlex.quote(self.path)} ]"


@dataclass(frozen=True)
class SamePhi:
    """Holds when study ``study`` has the same Φ* in the journals ``storage`` and ``other``."""
    storage: str
    other: str
    study: str

    def holds(self, root: Path) -> bool:
        return PhiFlags(self.storage, self.study).resolve(root) == PhiFlags(self.other, self.study).resolve(root)

    def shell(self) -> str:
        return f'[ "{PhiFlags(self.storage, self.study).text()}" = "{PhiFlags(self.other, self.study).text()}" ]'


Condition = Exists | Missing | SamePhi


def shell_guard(conditions: tuple[Condition, ...]) -> str:
    """The shell prefix that skips a command when every condition holds: ``[ c1 ] && [ c2 ] || ``."""
    return " && ".join(c.shell() for c in conditions) + " || " if conditions else ""


# -- arguments known when the command runs ----------------------------------------------------------------


@dataclass(frozen=True)
class PhiFlags:
    """Study ``study``'s Φ* in journal ``storage`` (the selected trial, else the best) as ermrl's flags."""
    storage: str
    study: str

    def resolve(self, root: Path) -> list[str]:
        """``["--sr", SR..., "--leak-rate", LR..., "--iss", ISS...]``, one value per reservoir, each the float's
        repr (what ``ermrl train`` reads back to the same float)."""
        from ermrl.evolution.record import decode_study_record
        from ermrl.evolution.selection import chosen_trial
        from ermrl.evolution.study import ATTR, load_study

        study = load_study(str(root / self.storage), self.study)
        _, phi, _ = chosen_trial(study, decode_study_record(study.user_attrs[ATTR]), None)
        flags = {"sr": "--sr", "lr": "--leak-rate", "iss": "--iss"}
        return [w for f in ("sr", "lr", "iss") for w in (flags[f], *(repr(float(v)) for v in getattr(phi, f)))]

    def text(self) -> str:
        return f"<Φ* of {self.study} in {self.storage}>"


@dataclass(frozen=True)
class FirstOf:
    """The first of ``paths`` that exists (a :class:`StopIf` before the command says what to do when none does)."""
    paths: tuple[str, ...]

    def resolve(self, root: Path) -> list[str]:
        found = next((p for p in self.paths if (root / p).exists()), None)
        if found is None:
            raise FileNotFoundError(f"none of {', '.join(self.paths)} exists")
        return [found]

    def text(self) -> str:
        return "<the first of " + " | ".join(self.paths) + " that exists>"


Arg = str | PhiFlags | FirstOf


# -- actions -------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Run:
    """One command. ``program``: "ermrl" (this interpreter's ``ermrl``, or ``$ERMRL``), "python" (this interpreter
    running a script of the repository) or "reference" (``$REF_PYTHON``, default ``.venv-ref/bin/python``). Skipped
    when every ``skip_if`` condition holds (none: it always runs, and resumes by itself). ``tee``: its output is
    also written to that file once it ends well (``append``: added to it); ``show=False`` discards the output."""
    program: str
    args: tuple[Arg, ...]
    skip_if: tuple[Condition, ...] = ()
    tee: str | None = None
    append: bool = False
    show: bool = True


@dataclass(frozen=True)
class Experiment:
    """``ermrl experiment run NAME --scale SCALE --storage docs/data/NAME-SCALE/studies.log --out
    runs/experiments/NAME-SCALE --baseline-store STORE ARGS``, between a restore and a collect and stash of its test
    phases' files (a stash also when the run is stopped)."""
    name: str
    scale: str
    args: tuple[str, ...] = ()

    @property
    def folder(self) -> str:
        return f"{self.name}-{self.scale}"

    def command(self) -> Run:
        return Run("ermrl", ("experiment", "run", self.name, "--scale", self.scale, "--storage",
                             f"docs/data/{self.folder}/studies.log", "--out", f"runs/experiments/{self.folder}",
                             "--baseline-store", STORE, *self.args))


@dataclass(frozen=True)
class Collect:
    """Copies the small files of each test phase under ``runs/experiments/FOLDER`` to ``docs/data/FOLDER``."""
    folder: str


@dataclass(frozen=True)
class CopyFiles:
    """Copies the files ``names`` of folder ``source`` into folder ``target`` (made if missing), unless every
    ``skip_if`` condition holds."""
    source: str
    target: str
    names: tuple[str, ...]
    skip_if: tuple[Condition, ...] = ()


@dataclass(frozen=True)
class Remove:
    """Removes the files matching each glob pattern, if any (``rm -f``)."""
    patterns: tuple[str, ...]


@dataclass(frozen=True)
class MakeDirs:
    """Makes a folder and its parents (``mkdir -p``), unless every ``skip_if`` condition holds."""
    path: str
    skip_if: tuple[Condition, ...] = ()


@dataclass(frozen=True)
class StopIf:
    """Ends the step, printing ``message``, when every condition holds."""
    conditions: tuple[Condition, ...]
    message: str


Action = Run | Experiment | Collect | CopyFiles | Remove | MakeDirs | StopIf


@dataclass(frozen=True)
class Step:
    """A step of the paper's reproduction: ``ermrl reproduce NAME`` runs its actions in order."""
    name: str
    claims: tuple[str, ...]
    description: str
    actions: tuple[Action, ...]


# -- shorthands for the declarations ------------------------------------------------------------------------


def _words(args) -> tuple[Arg, ...]:
    """``args`` flattened (tuples and lists spliced in), numbers as their text."""
    out: list[Arg] = []
    for a in args:
        if isinstance(a, (tuple, list)):
            out.extend(_words(a))
        else:
            out.append(a if isinstance(a, (PhiFlags, FirstOf)) else str(a))
    return tuple(out)


def ermrl(*args, skip_if: tuple[Condition, ...] = (), tee: str | None = None, append: bool = False,
          show: bool = True) -> Run:
    """``ermrl ARGS`` (tuples in ``args`` are spliced in)."""
    return Run("ermrl", _words(args), skip_if, tee, append, show)


def python(script: str, *args, tee: str | None = None, skip_if: tuple[Condition, ...] = ()) -> Run:
    """``python SCRIPT ARGS``, a script of the repository run by this interpreter."""
    return Run("python", _words((script, *args)), skip_if, tee)


def reference(script: str, *args, skip_if: tuple[Condition, ...] = ()) -> Run:
    """``$REF_PYTHON SCRIPT ARGS``: a script run by the reference pipeline's interpreter (SB3, ReservoirPy)."""
    return Run("reference", _words((script, *args)), skip_if)


def made(path: str) -> tuple[Condition, ...]:
    """Skip once ``path`` exists."""
    return (Exists(path),)


def done(run_folder: str) -> tuple[Condition, ...]:
    """Skip once ``run_folder/summary.json`` exists: the run ended."""
    return made(f"{run_folder}/summary.json")


def train_once(out: str, *args) -> Run:
    """``ermrl train ARGS --out OUT``, skipped once OUT/summary.json exists."""
    return ermrl("train", *args, "--out", out, skip_if=done(out))


def train_saved(out: str, *args) -> tuple[Run, Remove]:
    """``ermrl train ARGS`` on the test seeds, 10 × 1M, agents saved in OUT/agents/ (skipped once done), then its
    episodes.csv removed: the curves and the per-seed scores are in curves.csv and summary.json."""
    return (ermrl("train", "--seeds", "10", "--first-seed", "1000", "--timesteps", "1000000", *args, "--quiet",
                  "--out", out, skip_if=done(out)),
            Remove((f"{out}/episodes.csv",)))


def experiment(name: str, scale: str, *args) -> Experiment:
    return Experiment(name, scale, tuple(str(a) for a in _words(args)))


def compare(*args, tee: str | None = None, append: bool = False, show: bool = True) -> Run:
    """``ermrl compare ARGS``, its table also written to ``tee``."""
    return ermrl("compare", *args, tee=tee, append=append, show=show)


def flatten(*parts) -> tuple[Action, ...]:
    """The actions of ``parts`` (actions, or tuples of them) in order."""
    out: list[Action] = []
    for p in parts:
        out.extend(flatten(*p) if isinstance(p, (tuple, list)) else [p])
    return tuple(out)


def step(name: str, claims: str, description: str, *actions) -> Step:
    """A step; ``claims`` is space-separated (``"C1 C2"``, or ``""``)."""
    return Step(name, tuple(claims.split()), description, flatten(*actions))
