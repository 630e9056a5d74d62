"""The evolution report: figures and HTML built from a hand-made in-memory Optuna study (no training)."""

import json
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import optuna  # noqa: E402
import pytest  # noqa: E402
from optuna.distributions import FloatDistribution  # noqa: E402
from optuna.trial import TrialState, create_trial  # noqa: E402

from ermrl.analysis.report import fitness_over_trials, hp_map, write_report  # noqa: E402

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SPACE = {"sr": (1e-2, 10.0), "lr": (1e-2, 1.0), "iss": (1e-2, 10.0)}


def make_study(k: int, n_complete: int = 40, n_failed: int = 2, env_id: str = "CartPole-v1") -> optuna.Study:
    """A study laid out as ``ermrl evolve`` stores it; trial ``best`` (number 17 when present) has the top fitness."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(direction="maximize")
    study.set_user_attr("ermrl", {
        "env_id": env_id, "reservoirs": k, "seeds": 3, "timesteps": 10000, "sampler": "cmaes", "popsize": 8,
        "search_space": {name: list(b) for name, b in SPACE.items()},
        "train": {"ppo": {"learning_rate": 3e-4, "n_steps": 128}, "reservoir": {"units": 100}}})
    names = ["sr", "lr", "iss"] if k == 1 else [f"{n}_{i}" for i in range(1, k + 1) for n in ("sr", "lr", "iss")]
    dists = {n: FloatDistribution(*SPACE[n.split("_")[0]], log=True) for n in names}
    rng = np.random.default_rng(k)
    for i in range(n_complete + n_failed):
        params = {n: float(np.exp(rng.uniform(*np.log(SPACE[n.split("_")[0]])))) for n in names}
        phi = {h: [params[h if k == 1 else f"{h}_{r}"] for r in range(1, k + 1)] for h in ("sr", "lr", "iss")}
        attrs = {"phi": phi, "generation": i // 8}
        if i >= n_complete:
            study.add_trial(create_trial(params=params, distributions=dists, state=TrialState.FAIL,
                                         user_attrs={**attrs, "failure": "NaN loss <in PPO update>"}))
            continue
        value = 487.25 if i == 17 else float(rng.uniform(10, 400))
        seeds = [value - 1.0, value, value + 1.0]
        study.add_trial(create_trial(params=params, distributions=dists, value=value,
                                     user_attrs={**attrs, "seed_fitness": seeds}))
    return study


def tiny_png(path):
    fig, ax = plt.subplots(figsize=(1, 1))
    ax.plot([0, 1], [0, 1])
    fig.savefig(path, dpi=20)
    plt.close(fig)


@pytest.mark.parametrize("k", [1, 2])
def test_report_contents(tmp_path, k):
    study = make_study(k)
    best = study.best_trial
    assert best.number == 17 and best.value == 487.25
    out = write_report(study, tmp_path)
    assert out == tmp_path / "report.html" and out.is_file()
    doc = out.read_text()
    assert doc.count("data:image/png;base64,") >= 2
    for name in ("fitness_over_trials.png", "hp_map.png"):
        assert (tmp_path / name).read_bytes()[:8] == PNG_MAGIC
    # counts: completed / failed / total
    assert re.search(r"<td class=\"n\">40</td><td class=\"n\">2</td><td class=\"n\">42</td>", doc)
    # best Φ: trial number, fitness, every param, per-seed fitness
    best_section = doc[doc.index("Best &Phi;"):]
    # numbers rounded for reading (4 significant digits): 487.25 -> 487.2
    assert "487.2<" in best_section and "486.2<" in best_section and "488.2<" in best_section
    assert ">17<" in best_section
    for name, value in best.params.items():  # the leak rate spelled out: "lr" reads as a learning rate
        shown = name.replace("lr", "leak rate", 1)
        assert f"<td>{shown}</td>" in best_section and f"{value:.4g}" in best_section
    assert "<td>lr" not in best_section
    # config, with nested train dict flattened
    assert "CartPole-v1" in doc and "train.ppo.n_steps" in doc and "cmaes" in doc
    # failure reasons are escaped
    assert "NaN loss &lt;in PPO update&gt;" in doc and "<in PPO update>" not in doc
    assert "Test phase" not in doc and "no completed trial yet" not in doc
    assert "Software" not in doc  # a study from before the versions were recorded
    study.set_user_attr("software", {"python": "3.11.7", "cpu": "x86_64 AVX2", "jax": "0.10.2"})
    doc = write_report(study, tmp_path).read_text()
    software = doc[doc.index("<summary>Software (the study's first run) and the CPUs its trials ran on</summary>"):]
    assert "<td>cpu</td><td>x86_64 AVX2</td>" in software and "<td>jax</td><td>0.10.2</td>" in software
    assert "completed trials" not in software  # no trial records its CPU: no table of "not recorded" alone


def test_report_counts_the_cpus_the_trials_ran_on(tmp_path):
    study = make_study(1, n_complete=2, n_failed=0)
    first = study.trials[0]
    for cpu in ("x86_64 AVX2", "x86_64 AVX-512", "x86_64 AVX2", "x86_64 AVX2"):
        study.add_trial(create_trial(params=first.params, distributions=first.distributions, value=1.0,
                                     user_attrs={"generation": 1, "worker": {"host": "vm", "cpu": cpu}}))
    cpus = write_report(study, tmp_path).read_text().split("<th>completed trials</th>")[1].split("</table>")[0]
    assert re.findall(r"<td>([^<]+)</td><td class=\"n\">(\d+)</td>", cpus) == [
        ("x86_64 AVX2", "3"), ("not recorded", "2"), ("x86_64 AVX-512", "1")]


def test_report_test_phase(tmp_path):
    study = make_study(1, n_complete=10, n_failed=0)
    (tmp_path / "test").mkdir()
    tiny_png(tmp_path / "test" / "test_phase.png")
    rows = [{"model": "evolved ER-MRL", "env_id": "CartPole-v1", "final_mean": 451.5, "final_std": 12.25,
             "auc_mean": 301.75, "auc_std": 8.5, "n_seeds": 5},
            {"model": "PPO baseline", "env_id": "CartPole-v1", "final_mean": 210.125, "final_std": 30.0,
             "auc_mean": 150.0, "auc_std": 9.0, "n_seeds": 5}]
    (tmp_path / "test" / "summary.json").write_text(json.dumps(rows))
    out = write_report(study, tmp_path, out=tmp_path / "sub" / "r.html")
    assert out == tmp_path / "sub" / "r.html" and not (tmp_path / "report.html").exists()
    doc = out.read_text()
    assert doc.count("data:image/png;base64,") == 3
    section = doc[doc.index("Test phase"):]
    for text in ("evolved ER-MRL", "PPO baseline", "451.5", "12.25", "301.75", "210.125"):
        assert text in section


def test_report_test_phase_from_curves_csv(tmp_path):
    """Without test_phase.png the figure is redrawn from test/curves.csv via learning_curves."""
    study = make_study(1, n_complete=5, n_failed=0)
    (tmp_path / "test").mkdir()
    (tmp_path / "test" / "summary.json").write_text(json.dumps(
        [{"model": "m", "env_id": "CartPole-v1", "final_mean": 1.0, "final_std": 0.0, "auc_mean": 1.0, "auc_std": 0.0, "n_seeds": 2}]))
    lines = ["model,seed,timestep,mean_return_100"] + [f"m,{s},{t},{t + s}" for s in (0, 1) for t in (100, 200)]
    (tmp_path / "test" / "curves.csv").write_text("\n".join(lines) + "\n")
    doc = write_report(study, tmp_path).read_text()
    assert doc.count("data:image/png;base64,") == 3
    assert (tmp_path / "test_phase.png").read_bytes()[:8] == PNG_MAGIC


@pytest.mark.parametrize("n_failed", [0, 3])
def test_report_without_completed_trials(tmp_path, n_failed):
    study = make_study(2, n_complete=0, n_failed=n_failed)
    doc = write_report(study, tmp_path).read_text()
    assert "no completed trial yet" in doc and "Best &Phi;" not in doc
    assert doc.count("data:image/png;base64,") >= 2
    assert f'<td class="n">0</td><td class="n">{n_failed}</td><td class="n">{n_failed}</td>' in doc


def test_figures_standalone(tmp_path):
    study = make_study(3, n_complete=12, n_failed=1)
    for fn, name in ((fitness_over_trials, "f.png"), (hp_map, "h.png")):
        path = fn(study, tmp_path / "figs" / name)
        assert path == tmp_path / "figs" / name and path.read_bytes()[:8] == PNG_MAGIC
    assert hp_map(study, tmp_path / "top5.png", top=5).stat().st_size > 0


def test_report_embeds_the_analyses_it_finds(tmp_path):
    """Analyses written into the run folder (context figure, fft/probe figures with their Markdown tables, videos)
    appear after the test phases and before the evolution's figures; the configuration stays last."""
    study = make_study(1)
    tiny_png(tmp_path / "context.png")
    tiny_png(tmp_path / "fft.png")
    (tmp_path / "fft.md").write_text("| run | rhythm |\n|---|---|\n| ermrl | 0.91 |\n")
    tiny_png(tmp_path / "unrelated.png")  # no table beside it: not an analysis
    (tmp_path / "test" / "videos").mkdir(parents=True)
    (tmp_path / "test" / "videos" / "ermrl-seed1000.mp4").write_bytes(b"\0")
    doc = write_report(study, tmp_path).read_text()
    section = doc[doc.index("<h2>Analyses</h2>"):doc.index("<h2>Fitness over trials</h2>")]
    assert "<h3>context</h3>" in section and "<h3>fft</h3>" in section and "unrelated" not in section
    assert section.count("data:image/png;base64,") == 2 and "| ermrl | 0.91 |" in section
    assert '<a href="test/videos/ermrl-seed1000.mp4">' in section
    assert doc.index("<h2>Analyses</h2>") < doc.index("<summary>Configuration</summary>")
    assert "<h2>Analyses</h2>" not in write_report(make_study(1), tmp_path / "bare").read_text()


def test_running_time_counts_overlapping_trials_once_and_pauses_not_at_all(tmp_path):
    """Completed trials at [0, 10] s and [5, 15] s (two workers) and [20, 30] s: the study ran 15 + 10 = 25 s of its
    30 s span; a failed trial (its finish may be when another worker failed it, after a stop) and a running one do
    not count. The report's first table shows both times."""
    import datetime as dt

    from optuna.trial import FrozenTrial

    from ermrl.analysis.trials import running_time

    study = make_study(1, n_complete=0, n_failed=0)
    t0 = dt.datetime(2026, 11, 23, 8, 0, 0)
    dist = {"sr": FloatDistribution(*SPACE["sr"], log=True)}
    for number, (a, b, state) in enumerate([(0, 10, TrialState.COMPLETE), (5, 15, TrialState.COMPLETE),
                                            (20, 30, TrialState.COMPLETE), (25, 900, TrialState.FAIL),
                                            (41, None, TrialState.RUNNING)]):
        study.add_trial(FrozenTrial(
            number=number, state=state, value=100.0 + number if state == TrialState.COMPLETE else None,
            values=None, datetime_start=t0 + dt.timedelta(seconds=a),
            datetime_complete=None if b is None else t0 + dt.timedelta(seconds=b), params={"sr": 1.0},
            distributions=dist, user_attrs={"phi": {"sr": [1.0], "lr": [0.5], "iss": [1.0]}, "generation": 0},
            system_attrs={}, intermediate_values={}, trial_id=number))
    assert running_time(study) == (25.0, 30.0)
    text = write_report(study, tmp_path).read_text()
    assert "<td>0:00:25</td><td>0:00:30</td>" in text.replace("\n", "")
    assert running_time(make_study(1, n_complete=0, n_failed=0)) == (0.0, 0.0)


def test_a_test_phase_section_states_its_result_explains_its_curves_and_hides_ci_from_few_seeds(tmp_path):
    """The committed 900-trial CartPole test phase (10 seeds): one sentence with the best ER-MRL model against PPO
    on the same observation, the bands and *final* explained; a 3-seed P(improvement) shows no CI."""
    import shutil
    from pathlib import Path

    from ermrl import storage
    from ermrl.analysis.report import result_sentence, test_phase_section

    src = Path(__file__).resolve().parents[1] / "docs/data/partial-observability-paper/cartpole-1res/test"
    rows = storage.read_test_summary(src)
    # written before the labels of today, read in today's wording
    assert result_sentence(rows) == ("ER-MRL (learning rate 0.0003; sr 0.508, leak rate 0.0568, iss 1) ends at "
                                     "371.2 ± 148.0 (final, mean ± std over 10 seeds), above PPO (same observation)'s "
                                     "47.4 ± 5.7.")
    html_text = "".join(test_phase_section(src, tmp_path))
    assert "shaded bands ± one standard deviation (population, ddof 0)" in html_text
    assert "[" in html_text.split("P(improvement)")[1]  # 10 seeds: the CI is shown
    few = tmp_path / "few"
    shutil.copytree(src, few)
    data = json.loads((few / "summary.json").read_text())
    for row in (data if isinstance(data, list) else data["rows"]):
        row["n_seeds"] = 3
    (few / "summary.json").write_text(json.dumps(data))
    assert "no CI from 3 seeds" in "".join(test_phase_section(few, tmp_path))
