"""How a reproduction step keeps an experiment's test phases in the repository, between ``runs/experiments/F/``
(where ``ermrl experiment run`` works; not committed) and ``docs/data/F/`` (beside its journal; committed), F being
``NAME-SCALE``:

- :func:`collect`: after a run, each test phase's small files (summary, curves, settings, figure, selection) are
  copied to docs/data/F/, not its saved agents nor what a command regenerates in bulk (report.html, episodes.csv);
- :func:`stash`: the finished models of unfinished test phases (``OUT.partial/``, a few MB) are kept in
  docs/data/F/ too, also when the run is stopped, so that a run stopped with its machine resumes from a fresh
  checkout; a stashed folder goes once its test phase is written;
- :func:`restore`: the reverse, before a run; it also puts back the collected files of each finished test phase,
  so that ``experiment run`` on a fresh machine skips it instead of training it again;
- :func:`journals_elsewhere`: the journals under docs/data/ other than F's own that hold studies of the experiment
  at that scale (they would be ignored, and the studies evolved again).

Every path is relative to ``root``, the repository's root.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

KEPT = frozenset({"summary.json", "summary.csv", "curves.csv", "test_config.json", "test_phase.png", "report.md",
                  "selection.json"})
"""The files :func:`collect` copies."""


def _partials(folder: Path) -> list[Path]:
    """The ``*.partial`` folders anywhere under ``folder``."""
    return sorted(p for p in folder.rglob("*.partial") if p.is_dir()) if folder.is_dir() else []


def _copy_files(source: Path, target: Path) -> None:
    """Copies the files directly in ``source`` (not its folders) into ``target``, made if missing, with their
    modification times."""
    target.mkdir(parents=True, exist_ok=True)
    for f in sorted(source.iterdir()):
        if f.is_file():
            shutil.copy2(f, target / f.name)


def collect(root: Path, folder: str) -> list[Path]:
    """Copies the :data:`KEPT` files under ``runs/experiments/FOLDER`` (but not under an ``agents`` or
    ``*.partial`` folder) to the same places under ``docs/data/FOLDER``; returns the files written."""
    source, target = root / "runs/experiments" / folder, root / "docs/data" / folder
    written = []
    for f in sorted(source.rglob("*")) if source.is_dir() else []:
        rel = f.relative_to(source)
        if f.name in KEPT and f.is_file() and not any(p == "agents" or p.endswith(".partial") for p in rel.parts[:-1]):
            (target / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(f, target / rel)
            written.append(target / rel)
    return written


def stash(root: Path, folder: str) -> None:
    """Replaces each ``*.partial`` folder under docs/data/FOLDER by the files of the one under
    runs/experiments/FOLDER, and removes those of docs/data/FOLDER that runs/experiments/FOLDER no longer has (their
    test phases are written). Nothing when runs/experiments/FOLDER does not exist."""
    source, target = root / "runs/experiments" / folder, root / "docs/data" / folder
    if not source.is_dir():
        return
    for p in _partials(source):
        kept = target / p.relative_to(source)
        shutil.rmtree(kept, ignore_errors=True)
        _copy_files(p, kept)
    for p in _partials(target):
        if not (source / p.relative_to(target)).is_dir():
            shutil.rmtree(p)


def restore(root: Path, folder: str) -> None:
    """Puts back under runs/experiments/FOLDER each ``*.partial`` folder of docs/data/FOLDER whose test phase is
    neither there nor finished there, and the files of each finished test phase (a ``test/`` or ``test-ENV/``
    folder with a summary.json) that is not finished there."""
    source, target = root / "docs/data" / folder, root / "runs/experiments" / folder
    if not source.is_dir():
        return
    for p in _partials(source):
        rel = p.relative_to(source)
        if not (target / rel).is_dir() and not (target / rel.with_name(rel.name[: -len(".partial")]) /
                                                "summary.json").is_file():
            _copy_files(p, target / rel)
    for summary in sorted(source.rglob("summary.json")):
        phase = summary.parent
        if phase.name == "test" or phase.name.startswith("test-"):  # test-ENV: tested on another env
            rel = phase.relative_to(source)
            if not (target / rel / "summary.json").is_file():
                _copy_files(phase, target / rel)


def journals_elsewhere(root: Path, name: str, scale: str) -> list[Path]:
    """The journals ``docs/data/*/*.log`` other than ``docs/data/NAME-SCALE/studies.log`` that hold a study named
    ``NAME-SCALE-...``."""
    own = root / "docs/data" / f"{name}-{scale}" / "studies.log"
    pattern = re.compile(r'"study_name": *"' + re.escape(f"{name}-{scale}-"))
    found = []
    for journal in sorted((root / "docs/data").glob("*/*.log")):
        if journal != own and pattern.search(journal.read_text(encoding="utf-8", errors="replace")):
            found.append(journal)
    return found
