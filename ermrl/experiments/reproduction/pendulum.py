"""The reproduction's steps toward the PendulumNoVel target with the paper's PPO settings: evolutions at lr 1e-4,
at 500 units, at the paper's scale, and CMA-ES started near the default Φ (as data, see :mod:`.actions`)."""

from __future__ import annotations

from ermrl.experiments.reproduction.actions import (
    DEFAULT_PHI, NOT_SAVED, TEST10, CopyFiles, MakeDirs, PhiFlags, SamePhi, Step, StopIf, compare, ermrl, experiment,
    made, step, train_once, train_saved,
)

MEDIUM = "docs/data/reservoir-sizes-medium"
EVAL = "docs/data/deterministic-eval"
NEAR_DEFAULT = ("--min-sr", "0.1", "--max-sr", "10", "--min-leak-rate", "0.1", "--max-leak-rate", "1.0")
"""CMA-ES bounds around the default Φ (sr 0.95, lr 0.5): log middle sr 1, lr 0.32, where the search starts."""


def steps() -> list[Step]:
    return [pendulum_lr1e4(), pendulum_paper_500u(), pendulum_paper_500u_interim(), pendulum_500u_lr1e4(),
            pendulum_500u_near_default(), pendulum_500u_near_default_wide(), pendulum_500u_near_default_wide_50(),
            pendulum_500u_more_seeds(), pendulum_100u_near_default_wide()]


def medium_lr1e4(study: str, units: int) -> list:
    """A `medium` PendulumNoVel study (60 trials × 3 seeds × 300k, top 5 on 5 seeds) evolved and selected at lr
    1e-4, journal docs/data/STUDY/studies.log, then its Φ* trained on the test seeds (1000-1009 × 1M) at 1e-4 into
    docs/data/STUDY/ermrl/ (skipped once there)."""
    d = f"docs/data/{study}"
    where = ("--study", study, "--storage", f"{d}/studies.log", "--out", f"runs/{study}")
    return [ermrl("evolve", "--env", "PendulumNoVel-v1", "--units", units, "--reservoirs", 1, "--fixed-iss", "1.0",
                  "--trials", 60, "--seeds", 3, "--timesteps", 300000, "--learning-rate", "1e-4", where, "--quiet"),
            ermrl("select", where, "--top", 5, "--seeds", 5, "--quiet"),
            train_once(f"{d}/ermrl", "--env", "PendulumNoVel-v1", "--units", units,
                       PhiFlags(f"{d}/studies.log", study), "--seeds", 10, "--first-seed", 1000, "--timesteps",
                       1000000, "--learning-rate", "1e-4", NOT_SAVED)]


def pendulum_lr1e4() -> Step:
    d = "docs/data/pendulum-lr1e-4"
    # the PPO baselines on those seeds and budget are the `pendulum` step's test phase's: not trained again
    return step("pendulum_lr1e4", "C2 C6", "C6/H1: the medium PendulumNoVel study evolved and selected at lr 1e-4, the "
                "paper's rate for the masked tasks, then its Φ* on the test seeds (10 × 1M) at 1e-4",
                medium_lr1e4("pendulum-lr1e-4", 100),
                compare(f"Φ* evolved at 1e-4={d}/ermrl/summary.json", tee=f"{d}/summary.md"))


def pendulum_paper_500u() -> Step:
    return step("pendulum_paper_500u", "C2 C14", "the Pendulum target, C14's variant at the paper's scale: "
                "PendulumNoVel with 500 units, 900 trials × 3 seeds × 300k, top 5 on 5 seeds, test 10 × 1M (resumes "
                "by whole generations)", experiment("reservoir-sizes", "paper", "--only", "pendulum-500u", TEST10))


def pendulum_paper_500u_interim() -> Step:
    d = "docs/data/reservoir-sizes-paper/interim-trial55"
    return step("pendulum_paper_500u_interim", "C14", "pendulum_paper_500u ahead of its selection: the best Φ after "
                "150 of its 900 trials (trial 55) on the test seeds at lr 1e-4, against the medium 500-unit Φ* and "
                "the default Φ at 500 units",
                train_once(d, "--env", "PendulumNoVel-v1", "--units", 500, "--sr", "0.06239118054509163",
                           "--leak-rate", "0.11866375803947449", "--iss", "1.0", "--seeds", 10, "--first-seed", 1000,
                           "--timesteps", 1000000, "--learning-rate", "1e-4", NOT_SAVED),
                compare(f"paper-scale best after 150 trials={d}/summary.json",
                        f"medium Φ*={MEDIUM}/pendulum-500u/test/summary.json",
                        f"default Φ={MEDIUM}/default-phi-500u/summary.json",
                        "--compare", "paper-scale best after 150 trials", "medium Φ*",
                        "--compare", "paper-scale best after 150 trials", "default Φ",
                        "--title", "PendulumNoVel, 500 units: the paper-scale study's best Φ so far (trial 55), "
                                   "tested 10 × 1M at lr 1e-4",
                        "--figure", f"{d}/comparison.png", tee=f"{d}/comparison.md"))


def pendulum_500u_lr1e4() -> Step:
    d = "docs/data/pendulum-500u-lr1e-4"
    # the 3e-4 study's test phase first: its PPO rows (same seeds and budget) are the table's
    return step("pendulum_500u_lr1e4", "C2 C6", "the Pendulum target, as pendulum_lr1e4 at 500 units: C14's medium "
                "study evolved and selected at lr 1e-4, its Φ* on the test seeds at 1e-4, against the 3e-4-evolved "
                "Φ* and the default Φ",
                medium_lr1e4("pendulum-500u-lr1e-4", 500),
                compare(f"evolved at 3e-4={MEDIUM}/pendulum-500u/test/summary.json",
                        f"evolved at 1e-4={d}/ermrl/summary.json", f"default Φ={MEDIUM}/default-phi-500u/summary.json",
                        "--compare", "evolved at 1e-4", "evolved at 3e-4", "--compare", "evolved at 1e-4", "default Φ",
                        "--title", "PendulumNoVel, 500 units, medium evolutions at two learning rates",
                        "--figure", f"{d}/pendulum.png", tee=f"{d}/summary.md"))


def pendulum_500u_near_default() -> Step:
    s, d = "pendulum-500u-near-default", "docs/data/pendulum-500u-near-default"
    where = ("--study", s, "--storage", f"{d}/studies.log", "--out", f"runs/{s}")
    return step("pendulum_500u_near_default", "C2", "the Pendulum target, a departure from the paper's search: CMA-ES "
                "started at the default Φ's region, 500 units, fitness at the test budget (3 seeds × 1M at lr 1e-4), "
                "18 trials, top 3 on 3 seeds, then the Φ* on the test seeds",
                ermrl("evolve", "--env", "PendulumNoVel-v1", "--units", 500, "--reservoirs", 1, "--fixed-iss", "1.0",
                      "--trials", 18, "--seeds", 3, "--timesteps", 1000000, "--learning-rate", "1e-4", NEAR_DEFAULT, where,
                      "--quiet"),
                ermrl("select", where, "--top", 3, "--seeds", 3, "--quiet"),
                train_once(f"{d}/ermrl", "--env", "PendulumNoVel-v1", "--units", 500, PhiFlags(f"{d}/studies.log", s),
                           "--seeds", 10, "--first-seed", 1000, "--timesteps", 1000000, "--learning-rate", "1e-4", NOT_SAVED),
                compare(f"evolved near the default={d}/ermrl/summary.json",
                        f"default Φ={MEDIUM}/default-phi-500u/summary.json",
                        f"evolved at 3e-4 (medium)={MEDIUM}/pendulum-500u/test/summary.json",
                        "--compare", "evolved near the default", "default Φ",
                        "--compare", "evolved near the default", "evolved at 3e-4 (medium)",
                        "--title", "PendulumNoVel, 500 units, CMA-ES started near the default Φ, fitness at 1M",
                        "--figure", f"{d}/pendulum.png", tee=f"{d}/summary.md"))


def wide_evolution(study: str, storage: str, out: str, units: int, trials: int, *extra) -> tuple:
    """CMA-ES near the default Φ with the trials at the test budget (1M, lr 1e-4), each trial's fitness over 8
    seeds new for each generation, 10 Φ a generation."""
    return ermrl("evolve", "--env", "PendulumNoVel-v1", "--units", units, "--reservoirs", 1, "--fixed-iss", "1.0",
                 "--trials", trials, "--seeds", 8, "--popsize", 10, "--seed-schedule", "generation", "--timesteps",
                 1000000, "--learning-rate", "1e-4", NEAR_DEFAULT, "--study", study, "--storage", storage, "--out", out,
                 *extra, "--quiet")


def near_default_wide(units: int) -> list:
    """pendulum_500u_near_default's CMA-ES with 8 seeds a trial (:func:`wide_evolution`), 40 trials (4
    generations), top 4 on 8 seeds × 1M, then the Φ* on the test seeds with its agents saved (the model
    deterministic_eval evaluates)."""
    s = f"pendulum-{units}u-near-default-wide"
    storage = f"docs/data/{s}/studies.log"
    return [wide_evolution(s, storage, f"runs/{s}", units, 40),
            ermrl("select", "--study", s, "--storage", storage, "--out", f"runs/{s}", "--top", 4, "--seeds", 8,
                  "--quiet"),
            train_saved(f"{EVAL}/{s}", "--env", "PendulumNoVel-v1", "--units", units, "--learning-rate", "1e-4",
                        PhiFlags(storage, s))]


def pendulum_500u_near_default_wide() -> Step:
    d, t = "docs/data/pendulum-500u-near-default-wide", f"{EVAL}/pendulum-500u-near-default-wide"
    return step("pendulum_500u_near_default_wide", "C2", "the Pendulum target: pendulum_500u_near_default with 8 seeds "
                "a trial, new each generation, 10 Φ a generation, 40 trials, against the default Φ at 500 units, the "
                "3-seed near-default Φ* and the medium Φ*",
                near_default_wide(500),
                compare(f"evolved near the default, 8 seeds={t}/summary.json",
                        f"default Φ={MEDIUM}/default-phi-500u/summary.json",
                        "evolved near the default, 3 seeds=docs/data/pendulum-500u-near-default/ermrl/summary.json",
                        f"evolved at 3e-4 (medium)={MEDIUM}/pendulum-500u/test/summary.json",
                        "--compare", "evolved near the default, 8 seeds", "default Φ",
                        "--compare", "evolved near the default, 8 seeds", "evolved near the default, 3 seeds",
                        "--compare", "evolved near the default, 8 seeds", "evolved at 3e-4 (medium)",
                        "--title", "500 units, CMA-ES near the default Φ, 8 seeds a trial",
                        "--figure", f"{d}/pendulum.png", tee=f"{d}/summary.md"))


def pendulum_500u_near_default_wide_50() -> Step:
    d, s = "docs/data/pendulum-500u-near-default-wide-50", "pendulum-500u-near-default-wide"
    t = f"{EVAL}/pendulum-500u-near-default-wide"
    return step("pendulum_500u_near_default_wide_50", "C2", "the Pendulum target: pendulum_500u_near_default_wide's "
                "study (a copy of its journal) evolved to 50 trials (2 trials at a time), selected again, and a new Φ* "
                "on the test seeds if it changed",
                MakeDirs(d),
                CopyFiles(f"docs/data/{s}", d, ("studies.log",), skip_if=made(f"{d}/studies.log")),
                wide_evolution(s, f"{d}/studies.log", f"runs/{s}-50", 500, 50, "--batch", 2),
                ermrl("select", "--study", s, "--storage", f"{d}/studies.log", "--out", f"runs/{s}-50", "--top", 4,
                      "--seeds", 8, "--quiet", tee=f"{d}/selection.txt"),
                StopIf((SamePhi(f"{d}/studies.log", f"docs/data/{s}/studies.log", s),),
                       "the Φ* did not change: its test is step pendulum_500u_near_default_wide's"),
                train_saved(f"{d}/test", "--env", "PendulumNoVel-v1", "--units", 500, "--learning-rate", "1e-4",
                            PhiFlags(f"{d}/studies.log", s)),
                compare(f"50 trials={d}/test/summary.json", f"40 trials={t}/summary.json",
                        f"default Φ={MEDIUM}/default-phi-500u/summary.json",
                        "--compare", "50 trials", "40 trials", "--compare", "50 trials", "default Φ",
                        "--title", "500 units, CMA-ES near the default Φ, 8 seeds a trial, 50 trials",
                        "--figure", f"{d}/pendulum.png", tee=f"{d}/summary.md"))


def pendulum_500u_more_seeds() -> Step:
    d, s = "docs/data/pendulum-500u-near-default-wide/seeds-1010", "pendulum-500u-near-default-wide"
    t = f"{EVAL}/pendulum-500u-near-default-wide"
    more = ("--env", "PendulumNoVel-v1", "--units", 500, "--learning-rate", "1e-4", "--seeds", 10, "--first-seed", 1010,
            "--timesteps", 1000000, NOT_SAVED)
    # the target stays judged on the test seeds 1000-1009; these seeds only narrow the estimate
    return step("pendulum_500u_more_seeds", "C2", "the Pendulum target: the 8-seed near-default Φ* and the default Φ "
                "at 500 units on 10 more seeds (1010-1019), then over the 20 seeds 1000-1019",
                train_once(f"{d}/evolved", more, PhiFlags(f"docs/data/{s}/studies.log", s)),
                train_once(f"{d}/default", more, DEFAULT_PHI),
                compare(f"evolved near the default, 8 seeds={d}/evolved/summary.json",
                        f"default Φ={d}/default/summary.json", "--compare", "evolved near the default, 8 seeds",
                        "default Φ", "--title", "500 units, seeds 1010-1019", "--figure", f"{d}/pendulum.png",
                        tee=f"{d}/summary.md"),
                compare(f"evolved near the default, seeds 1000-1019={t}/summary.json,{d}/evolved/summary.json",
                        f"default Φ, seeds 1000-1019={MEDIUM}/default-phi-500u/summary.json,{d}/default/summary.json",
                        "--compare", "evolved near the default, seeds 1000-1019", "default Φ, seeds 1000-1019",
                        "--title", "500 units, seeds 1000-1019", "--figure", f"{d}/pendulum-20-seeds.png",
                        tee=f"{d}/summary.md", append=True))


def pendulum_100u_near_default_wide() -> Step:
    d = "docs/data/pendulum-100u-near-default-wide"
    t = f"{EVAL}/pendulum-100u-near-default-wide"
    return step("pendulum_100u_near_default_wide", "C2", "the same search at the paper's 100 units, against the "
                "default Φ at 100 units, the best earlier 100-unit Φ* (pendulum_lr1e4) and the 500-unit one",
                near_default_wide(100),
                compare(f"evolved near the default, 100 units={t}/summary.json",
                        "default Φ, 100 units=docs/data/fitness-1m/default-phi-pendulum/summary.json",
                        "evolved at 1e-4, 100 units=docs/data/pendulum-lr1e-4/ermrl/summary.json",
                        f"evolved near the default, 500 units={EVAL}/pendulum-500u-near-default-wide/summary.json",
                        "--compare", "evolved near the default, 100 units", "default Φ, 100 units",
                        "--compare", "evolved near the default, 100 units", "evolved at 1e-4, 100 units",
                        "--compare", "evolved near the default, 100 units", "evolved near the default, 500 units",
                        "--title", "100 units, CMA-ES near the default Φ, 8 seeds a trial",
                        "--figure", f"{d}/pendulum.png", tee=f"{d}/summary.md"))
