"""Figures and a self-contained HTML report for an Optuna study written by ``ermrl evolve``.

The study keeps its configuration in ``study.user_attrs["ermrl"]``; each completed trial has
``value`` = fitness (mean over seeds) and user_attrs {"phi": {"sr"|"lr"|"iss": [K floats]},
"seed_fitness": [S floats], "generation": int}; failed trials carry a "failure" reason instead.
"""

from __future__ import annotations

import collections
import html
import os
import sys
from pathlib import Path

import numpy as np
import optuna
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from optuna.trial import FrozenTrial

from ermrl import storage
from ermrl.analysis.html import img as _img
from ermrl.analysis.html import page
from ermrl.analysis.html import table as _table
from ermrl.analysis.plots import learning_curves
from ermrl.analysis.statistics import format_ci
from ermrl.analysis.trials import completed, failed, maximize, n_reservoirs, phi, ranked, running_time
from ermrl.errors import ConfigError
from ermrl.evolution.heartbeat import WORKER_ATTR
from ermrl.model_labels import PHI_NAMES, param_name

MARKERS = ("o", "^", "s", "D", "v", "P", "*", "X")


def _hms(seconds: float) -> str:
    s = round(seconds)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


def _save(fig, path: Path | str) -> Path:
    return storage.save_figure(fig, path, dpi=110)


def fitness_over_trials(study: optuna.Study, path: Path | str) -> Path:
    """Fitness of each completed trial by trial number, failed trials as red x at the bottom, best-so-far line."""
    done, bad = completed(study), failed(study)
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    if done:
        x = np.array([t.number for t in done])
        y = np.array([t.value for t in done])
        acc = np.maximum.accumulate if maximize(study) else np.minimum.accumulate
        ax.scatter(x, y, s=14, alpha=0.7, label=f"completed ({len(done)})")
        ax.step(x, acc(y), where="post", color="k", lw=1.5, label="best so far")
        bottom = y.min() - 0.05 * max(np.ptp(y), 1e-9)
    else:
        bottom = 0.0
        ax.text(0.5, 0.5, "no completed trial yet", transform=ax.transAxes, ha="center", va="center")
    if bad:
        ax.scatter([t.number for t in bad], [bottom] * len(bad), marker="x", color="red",
                   label=f"failed ({len(bad)})")
    ax.set_xlabel("trial")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("fitness (mean over seeds)")
    ax.set_title(f"{study.user_attrs.get('ermrl', {}).get('env_id', study.study_name)}: fitness over trials")
    ax.grid(alpha=0.3)
    if done or bad:
        ax.legend(fontsize=8)
    return _save(fig, path)


def hp_map(study: optuna.Study, path: Path | str, top: int = 30) -> Path:
    """Spectral radius × leak rate (log-log) coloured by fitness; the ``top`` best trials drawn large, black-edged.

    For K > 1 reservoirs, reservoir k's (sr_k, lr_k) of every trial is drawn with marker MARKERS[k].
    """
    k = n_reservoirs(study)
    trials = ranked(study)
    best = {t.number for t in trials[:top]}
    fig = Figure(figsize=(6.5, 5))
    ax = fig.subplots()
    if trials:
        values = np.array([t.value for t in trials])
        norm = Normalize(values.min(), values.max() if values.max() > values.min() else values.min() + 1)
        for r in range(k):
            pts = [(p["sr"][r], p["lr"][r], t.value, t.number in best) for t in trials
                   if len((p := phi(t, k)).get("sr", [])) > r and len(p.get("lr", [])) > r]
            if not pts:
                continue
            sr, lr, val, is_top = (np.array(c) for c in zip(*pts))
            marker = MARKERS[r % len(MARKERS)]
            for sel, size, edge in ((~is_top, 22, "none"), (is_top, 75, "k")):  # top trials drawn last, on top
                ax.scatter(sr[sel], lr[sel], c=val[sel], cmap="viridis", norm=norm, s=size, marker=marker,
                                edgecolors=edge, linewidths=0.9, alpha=0.85 if edge == "none" else 1.0)
            if k > 1:
                ax.scatter([], [], marker=marker, color="grey", label=f"reservoir {r + 1}")
        ax.scatter([], [], marker="o", facecolors="none", edgecolors="k", s=75, label=f"top {min(top, len(trials))}")
        fig.colorbar(ScalarMappable(norm=norm, cmap="viridis"), ax=ax, label="fitness")
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no completed trial yet", transform=ax.transAxes, ha="center", va="center")
    ax.set_xscale("log")
    ax.set_yscale("log")
    space = study.user_attrs.get("ermrl", {}).get("search_space", {})
    for name, setter in (("sr", ax.set_xlim), ("lr", ax.set_ylim)):
        if isinstance(space.get(name), (list, tuple)) and len(space[name]) == 2:
            lo, hi = space[name]
            setter(lo / 1.2, hi * 1.2)
    ax.set_xlabel("spectral radius (sr)")
    ax.set_ylabel("leak rate")
    ax.set_title("HP map")
    ax.grid(alpha=0.3, which="both")
    return _save(fig, path)


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, object]]:
    """Nested dict -> [("a.b.c", leaf)], leaves in insertion order."""
    rows = []
    for key, val in d.items():
        name = f"{prefix}{key}"
        rows += _flatten(val, name + ".") if isinstance(val, dict) and val else [(name, val)]
    return rows


def _test_figure(test_dir: Path, run_dir: Path) -> Path | None:
    """``test/test_phase.png``, else one redrawn from ``test/curves.csv`` (model, seed, timestep, value) if present."""
    if (test_dir / "test_phase.png").is_file():
        return test_dir / "test_phase.png"
    if not (test_dir / "curves.csv").is_file():
        return None
    return learning_curves(storage.read_curves_csv(test_dir / "curves.csv"), "test phase",
                           run_dir / f"{test_dir.name}_phase.png")[0]


MIN_CI_SEEDS = 5
"""Below this many seeds a bootstrap CI of P(improvement) is not shown: it would look more certain than it is."""


def result_sentence(rows: list[dict]) -> str | None:
    """One sentence stating a test phase's result: the best ER-MRL model's final score against the PPO baseline on
    the same observation, or None when the summary has neither."""
    scored = [r for r in rows if r.get("final_mean") is not None and r.get("final_std") is not None]
    ours = [r for r in scored if r.get("kind") == "ER-MRL"]
    ppo = [r for r in scored if r.get("kind") == "PPO"]
    if not ours or not ppo:
        return None
    best = max(ours, key=lambda r: r["final_mean"])
    base = next((r for r in ppo if "full observation" not in str(r.get("model"))), ppo[0])
    word = "above" if best["final_mean"] > base["final_mean"] else "below"
    return (f"{best['model']} ends at {best['final_mean']:.1f} ± {best['final_std']:.1f} (final, mean ± std over "
            f"{best.get('n_seeds')} seeds), {word} {base['model']}'s {base['final_mean']:.1f} ± {base['final_std']:.1f}.")


def test_phase_section(test_dir: Path, run_dir: Path) -> list[str]:
    """HTML of one test phase: its figure, then per model mean ± std, IQM with its 95% CI, diverged seeds, AUC
    and the probability of improvement over each PPO baseline."""
    rows = storage.read_test_summary(test_dir)
    if rows is None:
        return []
    env_id = rows[0].get("env_id", "")
    evolved_on = rows[0].get("evolved_on") or []
    parts = [f"<h3>Test phase on {html.escape(env_id)}</h3>"]
    if evolved_on and evolved_on != [env_id]:
        parts.append(f"<p>Φ* evolved on {html.escape(', '.join(evolved_on))} (generalization to an unseen env).</p>")
    if rows[0].get("phi_choice"):
        parts.append(f"<p>Φ*: {html.escape(rows[0]['phi_choice'])}</p>")
    fig = _test_figure(test_dir, run_dir)
    if fig is not None:
        parts.append(_img(fig, f"test phase on {env_id}"))
        parts.append("<p>Curves: the mean return of each agent's last 100 episodes at every update; lines are the mean "
                     "over seeds, shaded bands ± one standard deviation (population, ddof 0). <i>final</i> below is "
                     "the mean return of the last 10 training episodes, the paper's score, so it can differ from the "
                     "curve's end.</p>")
    if (sentence := result_sentence(rows)) is not None:
        parts.append(f"<p><b>{html.escape(sentence)}</b></p>")
    parts.append(_table(["model", "learning rate", "seeds", "final mean ± std", "final IQM [95% CI]", "diverged", "AUC mean ± std"], [
        [r.get("model", ""), r.get("learning_rate"), r.get("n_seeds"), _pm(r.get("final_mean"), r.get("final_std")),
         format_ci(r.get("final_iqm"), r.get("final_iqm_low"), r.get("final_iqm_high")), r.get("diverged", 0),
         _pm(r.get("auc_mean"), r.get("auc_std"))] for r in rows]))
    improvements = [[r["model"], b, f"{p:.2f} [{lo:.2f}, {hi:.2f}]" if (r.get("n_seeds") or 0) >= MIN_CI_SEEDS
                     else f"{p:.2f} (no CI from {r.get('n_seeds')} seeds)"] for r in rows
                    for b, (p, lo, hi) in r.get("improvement", {}).items()]
    if improvements:
        parts.append(_table(["model", "against", "P(improvement) [95% CI]"], improvements))
    return parts


def test_phase_sections(run_dir: Path, skipped: dict[Path, str] | None = None) -> list[str]:
    """HTML of every test phase of ``run_dir`` (:func:`test_phase_section`), a damaged one (its summary.json or
    curves.csv not what ermrl wrote) left out: it is added to ``skipped`` ({folder: the one-line reason}) and
    :func:`skipped_note` tells of it, so that one damaged file does not cost the whole report."""
    parts = []
    for d in test_dirs(run_dir):
        try:
            parts += test_phase_section(d, run_dir)
        except ConfigError as e:
            if skipped is not None:
                skipped[d] = str(e)
    return parts


def skipped_note(skipped: dict[Path, str]) -> list[str]:
    """A paragraph per damaged test phase left out of a report, each also warned of on stderr (one line)."""
    parts = []
    for d, reason in skipped.items():
        print(f"warning: skipped test phase {d}: {reason}", file=sys.stderr)
        parts.append(f'<p class="warn">skipped test phase {html.escape(str(d))}: {html.escape(reason)}</p>')
    return parts


def _pm(mean, std) -> str:
    return "—" if mean is None else f"{mean:.6g} ± {std:.6g}"


def test_dirs(run_dir: Path) -> list[Path]:
    """The study's test phases: ``test`` first, then ``test-ENV`` folders."""
    run_dir = Path(run_dir)
    found = [run_dir / "test"] + sorted(run_dir.glob("test-*"))
    return [d for d in found if (d / "summary.json").is_file()]


VIDEO_SUFFIXES = (".mp4", ".gif")


def analysis_section(run_dir: Path, out_dir: Path) -> list[str]:
    """HTML of the analyses found in ``run_dir``: ``context.png`` (``ermrl analyze context``), every figure in
    ``run_dir/analyses/`` or beside a Markdown table of the same name (``ermrl analyze fft|probe --out``) with
    that table, embedded; and links to the videos (``ermrl video``), relative to ``out_dir``."""
    figures = [f for f in [run_dir / "context.png", *sorted(run_dir.glob("analyses/*.png")),
                           *sorted(p for p in run_dir.glob("*.png") if p.with_suffix(".md").is_file())]
               if f.is_file()]
    videos = sorted(p for p in run_dir.rglob("videos/*") if p.suffix in VIDEO_SUFFIXES)
    if not figures and not videos:
        return []
    parts = ["<h2>Analyses</h2>"]
    for fig in dict.fromkeys(figures):
        parts += [f"<h3>{html.escape(fig.stem)}</h3>", _img(fig, fig.stem)]
        if fig.with_suffix(".md").is_file():
            parts.append(f"<pre>{html.escape(fig.with_suffix('.md').read_text())}</pre>")
    if videos:
        links = "".join(f'<li><a href="{html.escape(os.path.relpath(v, out_dir))}">{html.escape(v.name)}</a></li>'
                        for v in videos)
        parts.append(f"<h3>Videos</h3><ul>{links}</ul>")
    return parts


def spread_section(study: optuna.Study, record: dict, run_dir: Path) -> list[str]:
    """HTML of the Φ spread per generation (CMA-ES studies with a stored search distribution), the stop of the
    study's recorded convergence rule (else of the default rule) marked: ``phi_spread.png`` in run_dir."""
    from ermrl.analysis import spread
    from ermrl.evolution import convergence

    from ermrl.evolution.search_space import SearchSpace

    if record.get("sampler") != "cmaes" or not {"search_space", "reservoirs", "popsize"} <= set(record):
        return []
    space = SearchSpace.from_dict(record["reservoirs"], record["search_space"])
    trials = study.get_trials(deepcopy=False)
    dists = convergence.centers_and_spreads(trials, space)
    if not dists:
        return []
    stopped = convergence.recorded(study)
    rule = convergence.Convergence(stopped["width"], stopped["generations"]) if stopped else convergence.Convergence()
    verdict = convergence.judge(study, space, record["popsize"], rule, trials)
    where = ("not reached" if verdict.generation is None else
             f"generation {verdict.generation}, {verdict.trials} of {len(completed(study))} completed trials")
    projection = convergence.project(verdict.spread, rule) if verdict.generation is None else None
    if projection is not None:
        where += f"; {projection.describe()}"
    fig = spread.figure(dists, rule, verdict.generation, f"{study.study_name}: Φ spread per generation",
                        run_dir / "phi_spread.png")
    return ["<h2>&Phi; spread per generation</h2>",
            f"<p>the standard deviation, in decades, of the distribution CMA-ES sampled each generation from; the "
            f"rule {'the study stopped by' if stopped else 'of <code>--until-converged</code>'} ({html.escape(rule.describe())}): "
            f"{html.escape(where)}</p>", _img(fig, "Φ spread per generation")]


def ran_on(trials: list[FrozenTrial]) -> list[list]:
    """[[cpu, number of trials], ...] from each trial's worker record ("x86_64 AVX2"; "not recorded" for trials
    of ermrl versions before it), most trials first; [] when no trial records its CPU."""
    workers = (t.user_attrs.get(WORKER_ATTR) for t in trials)
    cpus = collections.Counter(w.get("cpu", "not recorded") if isinstance(w, dict) else "not recorded" for w in workers)
    return [[cpu, n] for cpu, n in cpus.most_common()] if set(cpus) - {"not recorded"} else []


def write_report(study: optuna.Study, run_dir: Path | str, out: Path | str | None = None) -> Path:
    """Writes ``<run_dir>/report.html`` (or ``out``), with fitness_over_trials.png and hp_map.png beside it in
    run_dir. Results come first (best and selected Φ, test phases with their statistics, the analyses found in
    run_dir), then the evolution's figures, failed trials, the configuration, and the software versions with the
    CPUs the trials ran on (collapsed)."""
    run_dir = Path(run_dir)
    out = Path(out) if out is not None else run_dir / "report.html"
    cfg = study.user_attrs.get("ermrl", {})
    k = n_reservoirs(study)
    done, bad, best = completed(study), failed(study), ranked(study)[:1]
    envs = cfg.get("envs") or [cfg.get("env_id", study.study_name)]
    title = f"ER-MRL evolution: {', '.join(envs)}"
    parts = [f"<h1>{html.escape(title)}</h1>", f"<p>study <code>{html.escape(study.study_name)}</code></p>"]
    generations = {t.user_attrs["generation"] for t in study.trials if "generation" in t.user_attrs}
    running, span = running_time(study)
    parts += [_table(["completed", "failed", "total", "generations", "running time", "first start to last finish"],
                     [[len(done), len(bad), len(study.trials), len(generations), _hms(running), _hms(span)]])]
    if not done:
        parts.append('<p class="warn">no completed trial yet</p>')
    stopped = study.user_attrs.get("converged")
    if isinstance(stopped, dict) and stopped.get("generation") is not None:
        parts.append(f"<p>stopped: CMA-ES converged at generation {stopped['generation']} ({stopped['trials']} "
                     f"trials), every parameter's spread below {stopped['width']:g} decades for "
                     f"{stopped['generations']} generations in a row</p>")

    if best:
        t = best[0]
        p = phi(t, k)
        parts += ["<h2>Best &Phi;</h2>",
                  _table(["trial", "fitness", "generation"], [[t.number, t.value, t.user_attrs.get("generation", "")]]),
                  _table(["param", "value"], [[param_name(n), v] for n, v in t.params.items()]),
                  _table(["reservoir"] + [PHI_NAMES.get(n, n) for n in p], [[r + 1] + [p[n][r] for n in p] for r in range(k)
                                                    if all(len(p[n]) > r for n in p)])]
        seeds = t.user_attrs.get("seed_fitness", [])
        if seeds:
            parts += [_table(["seed index", "fitness"], [[i, v] for i, v in enumerate(seeds)])]
        if t.user_attrs.get("env_scores"):
            parts += [_table(["env", "score", "nScore"], [[e, v, t.user_attrs["env_nscores"].get(e)]
                                                           for e, v in t.user_attrs["env_scores"].items()])]
    selection = study.user_attrs.get("selection")
    if selection:
        parts += [f"<h2>Selection of &Phi;*</h2><p>the top {len(selection['trials'])} trials re-evaluated on "
                  f"{len(selection['seeds'])} fresh seeds; selected: trial {selection['winner']}</p>",
                  _table(["trial", "evolution fitness", "fresh-seed fitness"],
                         [[n, a, b] for n, a, b in zip(selection["trials"], selection["evolution_values"],
                                                       selection["values"])])]
    if test_dirs(run_dir):
        skipped: dict[Path, str] = {}
        parts += ["<h2>Test phases</h2>", *test_phase_sections(run_dir, skipped), *skipped_note(skipped)]
    parts += analysis_section(run_dir, out.parent)

    parts += ["<h2>Fitness over trials</h2>",
              _img(fitness_over_trials(study, run_dir / "fitness_over_trials.png"), "fitness over trials"),
              "<h2>HP map</h2>", _img(hp_map(study, run_dir / "hp_map.png"), "HP map")]
    parts += spread_section(study, cfg, run_dir)
    if bad:
        parts += ["<h2>Failed trials</h2>", _table(["trial", "generation", "reason"], [
            [t.number, t.user_attrs.get("generation", ""), str(t.user_attrs.get("failure", ""))] for t in bad])]
    parts += ["<details><summary>Configuration</summary>",
              _table(["key", "value"], [[key, v] for key, v in _flatten(cfg)]), "</details>"]
    software, cpus = study.user_attrs.get("software") or {}, ran_on(done)
    if software or cpus:  # ermrl.provenance: what a seed-for-seed rerun needs
        parts += ["<details><summary>Software (the study's first run) and the CPUs its trials ran on</summary>",
                  *([_table(["package", "version"], [[key, v] for key, v in software.items()])] if software else []),
                  *([_table(["CPU", "completed trials"], cpus)] if cpus else []), "</details>"]
    storage.write_text(out, page(title, parts))
    return out
