"""The HP map across studies (`ermrl analyze hp-map`): small real studies in a storage, built with
``study.add_trial`` (no training), the CLI in a subprocess, and the points it draws checked against the trials."""

import csv
import zlib
from pathlib import Path

import matplotlib.image
import numpy as np
import optuna
import pytest
from optuna.trial import TrialState, create_trial

from ermrl.analysis.hp_map import (CSV_HEADER, StudyPoints, cross_study_hp_map, hp_map_points, leak_rate_table,
                                   points_csv)
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import load_study, make_sampler, open_study
from ermrl.evolution.record import encode_study_record
from ermrl.training import TrainConfig

from cli_runs import ermrl

optuna.logging.set_verbosity(optuna.logging.WARNING)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def make_study(url: str, name: str, env_ids: tuple[str, ...], k: int, n_complete: int, n_failed: int = 0,
               phi_attr: bool = True) -> optuna.Study:
    """An ``ermrl evolve`` study (its record, the search space's distributions) with hand-made trials. With
    ``phi_attr`` each trial stores Φ as evolve does (float32 values in user_attrs), else only its params. Failed
    trials get the largest sr so that drawing one would show."""
    space = SearchSpace(reservoirs=k, fixed_iss=1.0)
    config = EvolveConfig(train=TrainConfig(env_id=env_ids[0], total_timesteps=2048), space=space, trials=100,
                          seeds=2, sampler="random", envs=env_ids if len(env_ids) > 1 else ())
    study = open_study(url, name, make_sampler("random", 6, 0), encode_study_record(config))
    dists = space.distributions()
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    for i in range(n_complete + n_failed):
        params = {n: float(d.high if i >= n_complete and n.startswith("sr") else
                           np.exp(rng.uniform(np.log(d.low), np.log(d.high)))) for n, d in dists.items()}
        phi = {hp: [float(np.float32(params[n])) for n in space.names(hp)] for hp in ("sr", "lr")}
        attrs = {"generation": i // 6, **({"phi": {**phi, "iss": [1.0] * k}} if phi_attr else {})}
        if i >= n_complete:
            study.add_trial(create_trial(params=params, distributions=dists, state=TrialState.FAIL,
                                         user_attrs={**attrs, "failure": "diverged"}))
        else:
            study.add_trial(create_trial(params=params, distributions=dists, value=float(rng.uniform(10, 500)),
                                         user_attrs=attrs))
    return study


def expected_rows(study: optuna.Study, k: int, top: int) -> list[tuple]:
    """(rank, trial, reservoir, sr, lr) of the ``top`` best completed trials, computed here from the raw trials."""
    done = [t for t in study.trials if t.state == TrialState.COMPLETE]
    best = sorted(done, key=lambda t: (-t.value, t.number))[:top]
    rows = []
    for rank, t in enumerate(best, 1):
        for r in range(k):
            if "phi" in t.user_attrs:
                sr, lr = t.user_attrs["phi"]["sr"][r], t.user_attrs["phi"]["lr"][r]
            else:
                sr, lr = (t.params[hp if k == 1 else f"{hp}_{r + 1}"] for hp in ("sr", "lr"))
            rows.append((rank, t.number, r + 1, sr, lr))
    return rows


def read_points(path) -> dict[str, list[tuple]]:
    """{study: [(rank, trial, reservoir, sr, lr)]} from the CSV written beside the figure."""
    with open(points_csv(path), newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == CSV_HEADER
        out = {}
        for row in reader:
            out.setdefault(row["study"], []).append((int(row["rank"]), int(row["trial"]), int(row["reservoir"]),
                                                    float(row["sr"]), float(row["leak_rate"])))
    return out


@pytest.fixture(scope="module")
def journal(tmp_path_factory):
    """One journal file with a 1-reservoir study on CartPole (40 completed trials, 3 failed), a 1-reservoir study on
    Pendulum (12, Φ only in params), a 2-reservoir study on two envs (35) and a study with failed trials only."""
    url = str(tmp_path_factory.mktemp("studies") / "studies.log")
    make_study(url, "cp-1res", ("CartPoleNoVel-v1",), 1, 40, 3)
    make_study(url, "pd-1res", ("PendulumNoVel-v1",), 1, 12, phi_attr=False)
    make_study(url, "both-2res", ("CartPoleNoVel-v1", "PendulumNoVel-v1"), 2, 35, 2)
    make_study(url, "empty", ("CartPoleNoVel-v1",), 1, 0, 4)
    return url


def test_cli_draws_the_top_30_of_each_study_in_two_panels(journal, tmp_path):
    out = tmp_path / "figs" / "hp.png"
    r = ermrl("analyze", "hp-map", "cp-1res", "pd-1res", "both-2res", "--storage", journal, "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert f"wrote {out}, {out.with_suffix('.csv')} and {out.with_suffix('.md')}" in r.stdout
    table = out.with_suffix(".md").read_text()
    assert table.startswith("Top 30 trials of each study") and table.split("\n\n", 1)[1] in r.stdout
    rows = {line.split(" | ")[0].strip("| "): line for line in table.splitlines() if line.startswith("| cp-1res")
            or line.startswith("| pd-1res") or line.startswith("| both-2res")}
    assert "| CartPoleNoVel-v1 | 1 | 30 |" in rows["cp-1res"] and "| PendulumNoVel-v1 | 1 | 12 |" in rows["pd-1res"]
    assert rows["both-2res"].endswith("| — (no other study of this K) |")  # the only 2-reservoir study
    assert out.read_bytes()[:8] == PNG_MAGIC
    height, width, _ = matplotlib.image.imread(out).shape
    assert 400 < height < 800 and width > 1.8 * height  # two panels side by side

    points = read_points(out)
    assert list(points) == ["cp-1res", "pd-1res", "both-2res"]
    for name, k, n in (("cp-1res", 1, 30), ("pd-1res", 1, 12), ("both-2res", 2, 30)):
        study = load_study(journal, name)
        assert points[name] == expected_rows(study, k, 30), name
        assert len(points[name]) == n * k
    with open(out.with_suffix(".csv"), newline="") as f:
        envs = {row["study"]: row["envs"] for row in csv.DictReader(f)}
    assert envs == {"cp-1res": "CartPoleNoVel-v1", "pd-1res": "PendulumNoVel-v1",
                    "both-2res": "CartPoleNoVel-v1+PendulumNoVel-v1"}


def test_default_storage_is_each_studys_sqlite_in_runs(tmp_path):
    for name, env in (("a", "CartPoleNoVel-v1"), ("b", "PendulumNoVel-v1")):
        make_study(f"sqlite:///{tmp_path}/runs/{name}/study.db", name, (env,), 1, 9)
    r = ermrl("analyze", "hp-map", "a", "b", "a", "--top", "5", "--out", "hp.png", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    height, width, _ = matplotlib.image.imread(tmp_path / "hp.png").shape
    assert width < 1.5 * height  # one panel: every study has 1 reservoir
    points = read_points(tmp_path / "hp.png")
    assert list(points) == ["a", "b"]  # a study named twice is drawn once
    for name in ("a", "b"):
        assert points[name] == expected_rows(load_study(f"sqlite:///{tmp_path}/runs/{name}/study.db", name), 1, 5)


def test_python_api_returns_the_path_and_draws_hp_map_points(journal, tmp_path):
    studies = [load_study(journal, n) for n in ("both-2res", "cp-1res")]
    path = cross_study_hp_map(studies, tmp_path / "hp.svg", top=7)
    assert path == tmp_path / "hp.svg" and path.read_text().lstrip().startswith("<?xml")
    series = hp_map_points(studies, top=7)
    assert [(s.study, s.reservoirs, s.sr.shape, s.lr.shape) for s in series] == [
        ("both-2res", 2, (7, 2), (7, 2)), ("cp-1res", 1, (7, 1), (7, 1))]
    assert series[0].envs == ("CartPoleNoVel-v1", "PendulumNoVel-v1")
    drawn = read_points(path)
    for s, study in zip(series, studies):
        assert drawn[s.study] == expected_rows(study, s.reservoirs, 7)
        assert list(s.trials) == [row[1] for row in expected_rows(study, s.reservoirs, 7)][:: s.reservoirs]


def test_bad_input_is_one_line_and_exit_code_2(journal, tmp_path):
    cases = [
        (["nope", "--out", "x.png"],
         "no study 'nope': runs/nope/study.db does not exist; run `ermrl evolve --study nope` first or pass --storage"),
        (["cp-1res", "nope", "--storage", journal, "--out", "x.png"],
         f"no study 'nope' in '{journal}'; studies there: cp-1res, pd-1res, both-2res, empty"),
        (["cp-1res", "--storage", str(tmp_path / "missing.log"), "--out", "x.png"],
         f"no study 'cp-1res': {tmp_path / 'missing.log'} does not exist; run `ermrl evolve --study cp-1res` first "
         "or pass --storage"),
        (["cp-1res", "empty", "--storage", journal, "--out", "x.png"],
         "study 'empty' has no completed trial; run `ermrl evolve --study empty` until one completes"),
        (["cp-1res", "--storage", journal, "--top", "0", "--out", "x.png"], "--top must be >= 1, got 0"),
        (["cp-1res", "--storage", journal, "--out", "x.txt"],
         "cannot write a figure as .txt; give a path ending in .png, .svg or .pdf"),
    ]
    size = Path(journal).stat().st_size
    for args, message in cases:
        r = ermrl("analyze", "hp-map", *args, cwd=tmp_path)
        assert r.returncode == 2 and r.stderr == f"ermrl analyze: error: {message}\n", (args, r.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no database, figure or CSV written
    assert Path(journal).stat().st_size == size


def test_help():
    r = ermrl("analyze", "hp-map", "--help")
    assert r.returncode == 0
    for flag in ("STUDY", "--storage", "--top", "--out"):
        assert flag in r.stdout, flag
    assert "analyze" in ermrl("--help").stdout and "hp-map" in ermrl("analyze", "--help").stdout


def points(name: str, lr: list[list[float]], sr: float = 1.0) -> StudyPoints:
    """A study's top trials with the given leak rates, (N, K), and one spectral radius."""
    lr = np.array(lr, np.float64)
    return StudyPoints(study=name, envs=(f"{name}-v5",), trials=np.arange(len(lr)),
                       fitness=-np.arange(len(lr), dtype=float), sr=np.full(lr.shape, sr), lr=lr,
                       bounds={"sr": (0.01, 10), "lr": (0.01, 1)})


def test_leak_rate_table_names_the_study_whose_leak_rates_are_lower():
    """Five trials of 'ant' all below the six of the two other studies: the exact two-sided Mann–Whitney p of a
    complete separation of 5 against 6 is 2 / C(11, 5) = 2 / 462."""
    table = leak_rate_table([points("ant", [[0.01], [0.02], [0.03], [0.04], [0.05]]),
                             points("cheetah", [[0.2], [0.4], [0.6]], sr=2.0), points("swimmer", [[0.3], [0.5], [0.7]]),
                             points("two", [[0.1, 0.5], [0.3, 0.9]])])
    rows = {line.split(" | ")[0].strip("| "): line for line in table.splitlines()[2:]}
    assert rows["ant"] == ("| ant | ant-v5 | 1 | 5 | 1 | 0.03 | lower (median 0.03 vs 0.45), "
                           "Mann–Whitney p = 0.0043, 5 vs 6 reservoirs |")
    assert "| cheetah-v5 | 1 | 3 | 2 | 0.4 | higher (median 0.4 vs 0.045)" in rows["cheetah"]
    assert rows["two"] == "| two | two-v5 | 2 | 2 | 1 (1 / 1) | 0.4 (0.2 / 0.7) | — (no other study of this K) |"
    same = leak_rate_table([points("a", [[0.1], [0.2], [0.3]]), points("b", [[0.1], [0.2], [0.3]])])
    assert "| a | a-v5 | 1 | 3 | 1 | 0.2 | the same median (median 0.2 vs 0.2), Mann–Whitney p = 1, 3 vs 3 reservoirs |" in same
