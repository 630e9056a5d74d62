"""Every file ermrl writes or reads, in one place: run folders, curves, summaries, tables.

Every write goes to a temporary file in the same folder, is flushed to disk and renamed over the target, so a
crash never leaves a half-written file behind; a folder of results is written beside its place and moved in whole
(:func:`staged_folder`). Output paths are checked before any work (:func:`check_folder`, :func:`check_file`).
Configs are written and read with their typed codec (:mod:`ermrl.codec`); the study record is in
:mod:`ermrl.evolution.record`.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import types
import typing
from pathlib import Path

import numpy as np

from ermrl import model_labels, provenance, summary_schema
from ermrl.atomic import atomic_path, check_file, check_folder, repair_journal, staged_folder  # noqa: F401
from ermrl.codec import OMIT_WHEN_DEFAULT, from_dict, to_dict  # noqa: F401  (the configs' codec, re-exported)
from ermrl.codec import json_default as _json_default
from ermrl.errors import ConfigError

# -- writing (atomic_path, staged_folder, check_folder, check_file, repair_journal: ermrl.atomic) ----------


def save_figure(fig, path: Path | str, dpi: int = 120) -> Path:
    """Writes the matplotlib figure ``fig`` (a ``matplotlib.figure.Figure``, drawn without pyplot) to ``path`` as PNG,
    atomically, after ``tight_layout``."""
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    return Path(path)


def write_text(path: Path | str, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_json(path: Path | str, obj) -> Path:
    return write_text(path, json.dumps(obj, indent=2, default=_json_default) + "\n")


def read_json(path: Path | str):
    return json.loads(Path(path).read_text(encoding="utf-8"))


def write_csv(path: Path | str, header: list[str], rows) -> Path:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return write_text(path, buf.getvalue())


def _float_or_none(v) -> float | None:
    return None if v is None or not np.isfinite(v) else float(v)


# -- curves and episodes ---------------------------------------------------------------------------------

Curves = dict[str, tuple[np.ndarray, np.ndarray]]
"""{model label: (timesteps (I,), values (S, I))}, values the mean return of the last 100 episodes."""


def write_curves_csv(path: Path, curves: Curves, seeds: dict[str, np.ndarray]) -> Path:
    """Long format: model, seed, timestep, value (mean return of the last 100 episodes)."""
    rows = ([label, int(s), int(t), "" if np.isnan(v) else f"{v:.6g}"]
            for label, (steps, values) in curves.items() for s, row in zip(seeds[label], values)
            for t, v in zip(steps, row))
    return write_csv(path, ["model", "seed", "timestep", "mean_return_100"], rows)


def read_curves_csv(path: Path) -> Curves:
    """Inverse of :func:`write_curves_csv`: {model: (timesteps (I,), values (S, I))}, NaN where a seed has none;
    a model labelled by an older version under its label today (:func:`ermrl.model_labels.current`).

    Raises ConfigError naming the file when it is not a curves file."""
    cells: dict[str, dict[int, dict[int, float]]] = {}
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            for row in reader:
                if None in row or None in row.values():  # a cut or damaged line: too few or too many fields
                    fields = [v for k, v in row.items() if k is not None and v is not None] + row.get(None, [])
                    raise ValueError(f"line {reader.line_num} has {len(fields)} fields, not {len(reader.fieldnames)}")
                val = float(row["mean_return_100"]) if row["mean_return_100"] else np.nan
                model = model_labels.current(row["model"])
                cells.setdefault(model, {}).setdefault(int(row["seed"]), {})[int(row["timestep"])] = val
        if not cells:
            raise ValueError("no rows")
    except (KeyError, ValueError, TypeError) as e:
        raise ConfigError(f"{path} is not a curves file written by ermrl ({type(e).__name__}: {e}); "
                          "rerun the command that wrote it") from None
    curves = {}
    for model, by_seed in cells.items():
        steps = np.array(sorted({t for s in by_seed.values() for t in s}))
        curves[model] = (steps, np.array([[s.get(t, np.nan) for t in steps] for s in by_seed.values()]))
    return curves


def write_episodes_csv(path: Path, results, label: str = "") -> Path:
    """One row per completed episode: model, agent, seed, timestep, return, length."""
    rows = ([label, a, int(results.seeds[a]), int(t), f"{r:.6g}", int(n)]
            for a, ep in enumerate(results.episodes) for t, r, n in zip(ep.timestep, ep.ret, ep.length))
    return write_csv(path, ["model", "agent", "seed", "timestep", "return", "length"], rows)


def results_summary(results) -> dict:
    """JSON-ready per-agent fitness and timing of a :class:`~ermrl.training.results.Results`."""
    fit = results.fitness()
    return {
        "env_id": results.env_id,
        "total_timesteps": results.total_timesteps,
        "seeds": results.seeds.tolist(),
        "fitness": [_float_or_none(v) for v in fit],
        "mean_fitness": None if np.all(np.isnan(fit)) else float(np.nanmean(fit)),
        "episodes": [len(e.ret) for e in results.episodes],
        "diverged": (~results.finite).tolist(),
        "compile_s": results.compile_s,
        "train_s": results.train_s,
        "agent_steps_per_s": results.agent_steps_per_s(),
    }


# -- run folders -----------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class TrainRun:
    """The files of a run folder written by ``ermrl train``."""

    folder: Path

    @property
    def config(self) -> Path:
        return self.folder / "config.json"

    @property
    def episodes(self) -> Path:
        return self.folder / "episodes.csv"

    @property
    def curves(self) -> Path:
        return self.folder / "curves.csv"

    @property
    def summary(self) -> Path:
        return self.folder / "summary.json"

    @property
    def figure(self) -> Path:
        return self.folder / "learning_curve.png"


def write_train_run(out: Path, config, results, label: str, effective: dict | None = None) -> TrainRun:
    """Writes config.json (the effective config and the software versions, :mod:`ermrl.provenance`),
    episodes.csv, curves.csv and summary.json into ``out``."""
    run = TrainRun(Path(out))
    population = {"seeds": results.seeds.tolist(), "phi": {k: v.tolist() for k, v in results.phi.items()},
                  "learning_rate": results.learning_rate.tolist()}
    write_json(run.config, {"train": to_dict(config), "population": population,
                            **({"options": effective} if effective else {}), "software": provenance.software()})
    write_episodes_csv(run.episodes, results, label)
    write_curves_csv(run.curves, {label: results.curves()}, {label: results.seeds})
    write_json(run.summary, results_summary(results))
    return run


RUN_RECORDS = {"train": ("config.json", "`ermrl train`"), "test": ("test_config.json", "`ermrl test`")}
"""{kind of run folder: (the record it always holds, the command that writes it)}."""


def run_kind(folder: Path | str) -> str | None:
    """"train" or "test" when ``folder`` holds that kind of run's record (:data:`RUN_RECORDS`), else None."""
    folder = Path(folder)
    if (folder / RUN_RECORDS["test"][0]).is_file():
        return "test"
    try:
        record = read_json(folder / RUN_RECORDS["train"][0])
    except (OSError, ValueError):
        return None
    return "train" if isinstance(record, dict) and "train" in record else None


def check_rerun_folder(folder: Path | str, kind: str, flag: str = "`out`") -> Path:
    """``folder`` if a run of ``kind`` may be written there: it is missing, empty, or holds such a run (a rerun
    replaces its files). Otherwise ConfigError before any work: a rerun removes its old agents, so a folder of
    other files (a test phase given to ``ermrl train``, the current folder) is never written into."""
    folder = Path(folder)
    names = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
    if names and run_kind(folder) != kind:
        record, command = RUN_RECORDS[kind]
        shown = ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")
        raise ConfigError(f"{flag} {folder} holds files that {command} did not write ({shown}) and no {record} "
                          f"of its run; give a new or empty folder, or one that {command} wrote")
    return folder


def run_env_id(folder: Path) -> str | None:
    """The env id a run folder was trained on, from its config.json (None when it has none)."""
    path = Path(folder) / "config.json"
    if not path.is_file():
        return None
    try:
        return read_json(path)["train"]["env_id"]
    except (KeyError, TypeError, ValueError):
        return None


# -- test phases -----------------------------------------------------------------------------------------


def write_test_summary(out: Path, rows: list[dict]) -> tuple[Path, Path]:
    """summary.json (every field) and summary.csv (one line per model) of a test phase."""
    keys = ["model", "env_id", "n_seeds", "learning_rate", "final_mean", "final_std", "final_iqm", "final_iqm_low",
            "final_iqm_high", "auc_mean", "auc_std", "diverged"]
    csv_rows = [[_fmt_cell(r.get(k, "")) for k in keys] for r in rows]
    return write_json(out / "summary.json", rows), write_csv(out / "summary.csv", keys, csv_rows)


def _fmt_cell(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return "" if v is None else str(v)


def read_test_summary(out: Path) -> list[dict] | None:
    """The rows (one per model) of the test phase in folder ``out`` (its summary.json); None when it has none. A
    model labelled by an older version reads under its label today (:func:`ermrl.model_labels.current`).

    Raises a one-line ConfigError naming the file when it is not a summary that ermrl wrote: not JSON (cut short,
    not UTF-8), not a non-empty list of rows, or a row without a field it needs or with a
    value of the wrong type (:mod:`ermrl.summary_schema`)."""
    path = Path(out) / "summary.json"
    if not path.is_file():
        return None
    problem = test_summary_problem(out)
    if problem is not None:
        env = Path(out).name.removeprefix("test-") if Path(out).name.startswith("test-") else None
        raise ConfigError(f"{problem}; rerun `ermrl test{' --env ' + env if env else ''}` to write it again")
    return [_current_labels(row) for row in read_json(path)]


def _current_labels(row: dict) -> dict:
    """A test summary's row with its model's label, and those its improvement is over, in today's wording."""
    row = {**row, "model": model_labels.current(row["model"])}
    if isinstance(row.get("improvement"), dict):
        row["improvement"] = {model_labels.current(k): v for k, v in row["improvement"].items()}
    return row


def test_summary_problem(out: Path) -> str | None:
    """Why ``out/summary.json`` is not a test phase's summary written by ermrl, as "PATH is damaged (...)"; None
    when it is one (or when there is none)."""
    path = Path(out) / "summary.json"
    if not path.is_file():
        return None
    try:
        rows = read_json(path)
    except ValueError as e:  # JSONDecodeError (cut short, not JSON), UnicodeDecodeError (not text)
        what = f"{type(e).__name__}: {(str(e).strip().splitlines() or [''])[0]}"
    else:
        what = summary_schema.rows_problem(rows)
    return None if what is None else f"{path} is damaged or was not written by `ermrl test` ({what})"


# -- the study record --------------------------------------------------------------------------------------

