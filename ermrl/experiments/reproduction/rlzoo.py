"""The reproduction's steps that judge the targets on rl-zoo's terms: deterministic evaluation of the best
configurations, rl-zoo's PendulumNoVel recipe taken apart piece by piece, and the recurrent baselines (C2, C5; as
data, see :mod:`.actions`)."""

from __future__ import annotations

from ermrl.experiments.reproduction.actions import (
    DEFAULT_PHI, MakeDirs, PhiFlags, Remove, Step, compare, ermrl, python, step, train_once, train_saved,
)

EVAL = "docs/data/deterministic-eval"
NEAR = "pendulum-500u-near-default-wide"
NEAR_PHI = PhiFlags(f"docs/data/{NEAR}/studies.log", NEAR)
SEEDS_1010 = f"docs/data/{NEAR}/seeds-1010"
ZOO = ("--n-envs", "4", "--n-steps", "1024", "--gamma", "0.9", "--gae-lambda", "0.95", "--n-epochs", "10", "--learning-rate",
       "1e-3", "--clip-range", "0.2", "--ent-coef", "0.0")
"""rl-baselines3-zoo's tuned PendulumNoVel-v1 scalar settings (hyperparams/ppo_lstm.yml)."""
ZOO_SDE = (*ZOO, "--use-sde", "--sde-sample-freq", "4")
"""The same with gSDE, a new exploration matrix every 4 steps."""
RLZOO_PENDULUM = (*ZOO_SDE, "--normalize")
"""rl-zoo's PendulumNoVel-v1 recipe as far as ermrl follows it: its settings, gSDE and input normalization."""
RLZOO_POLICY = ("--net-arch", "64", "--activation", "relu", "--no-ortho-init")
"""rl-zoo's policy: one 64-unit hidden layer, ReLU, no orthogonal init."""


def steps() -> list[Step]:
    return [deterministic_eval(), pendulum_rlzoo_ppo(), pendulum_normalize(), pendulum_rlzoo_sde(),
            pendulum_rlzoo_policy(), pendulum_rlzoo_evolve(), pendulum_rlzoo_lstm(), recurrent_vs_ermrl()]


def _dev(out: str, *args) -> tuple:
    """``ermrl train ARGS`` on the development seeds 1010-1019, 10 × 1M, agents not saved, then its episodes.csv
    removed."""
    return (train_once(out, *args, "--seeds", 10, "--first-seed", 1010, "--timesteps", 1000000, "--no-save-agents",
                       "--quiet"), Remove((f"{out}/episodes.csv",)))


def _evaluate(out: str, *runs: str) -> tuple:
    return ermrl("analyze", "evaluate", *runs, "--episodes", 50, "--out", out)


FOUR = ("evolved-500u", "default-phi-500u", "ppo", "ppo-full-obs")
"""The four models of a recipe tried on the test seeds (:func:`_four`)."""


def _four(d: str, reservoir: tuple, ppo: tuple) -> list:
    """The near-default Φ* and the default Φ at 500 units with the flags ``reservoir``, and PPO masked and with full
    observation with the flags ``ppo``, each on the test seeds with its agents saved in ``d/`` (:data:`FOUR`)."""
    return [train_saved(f"{d}/evolved-500u", "--env", "PendulumNoVel-v1", "--units", 500, reservoir, NEAR_PHI),
            train_saved(f"{d}/default-phi-500u", "--env", "PendulumNoVel-v1", "--units", 500, DEFAULT_PHI, reservoir),
            train_saved(f"{d}/ppo", "--env", "PendulumNoVel-v1", "--no-reservoir", ppo),
            train_saved(f"{d}/ppo-full-obs", "--env", "Pendulum-v1", "--no-reservoir", ppo)]


def deterministic_eval() -> Step:
    d, units = EVAL, {"500u-near-default": 500, "500u-near-default-wide": 500, "100u-near-default-wide": 100,
                      "500u-lr1e-4": 500, "lr1e-4": 100}
    return step("deterministic_eval", "C2", "the targets on rl-zoo's metric: the best configurations trained again on "
                "the test seeds (agents saved), then each evaluated with its deterministic policy over 50 fresh "
                "episodes",
                train_saved(f"{d}/pendulum-default-phi-500u", "--env", "PendulumNoVel-v1", "--units", 500, DEFAULT_PHI,
                            "--learning-rate", "1e-4"),
                train_saved(f"{d}/pendulum-medium-500u", "--env", "PendulumNoVel-v1", "--units", 500, "--learning-rate",
                            "1e-4", PhiFlags("docs/data/reservoir-sizes-medium/studies.log",
                                     "reservoir-sizes-medium-pendulum-500u")),
                # the other evolved Pendulum Φ*: steps pendulum_{500u,500u_wide,100u_wide}_near_default and
                # pendulum{_500u,}_lr1e4
                [train_saved(f"{d}/pendulum-{s}", "--env", "PendulumNoVel-v1", "--units", n, "--learning-rate", "1e-4",
                             PhiFlags(f"docs/data/pendulum-{s}/studies.log", f"pendulum-{s}"))
                 for s, n in units.items()],
                train_saved(f"{d}/pendulum-default-phi", "--env", "PendulumNoVel-v1", DEFAULT_PHI, "--learning-rate", "1e-4"),
                train_saved(f"{d}/pendulum-ppo", "--env", "PendulumNoVel-v1", "--no-reservoir", "--learning-rate", "3e-4"),
                train_saved(f"{d}/pendulum-ppo-full-obs", "--env", "Pendulum-v1", "--no-reservoir", "--learning-rate", "3e-4"),
                train_saved(f"{d}/cartpole-fitness-1m", "--env", "CartPoleNoVel-v1", "--learning-rate", "1e-4",
                            PhiFlags("docs/data/fitness-1m/studies.log", "cartpole-1res-fitness-1m")),
                train_saved(f"{d}/cartpole-paper", "--env", "CartPoleNoVel-v1", "--learning-rate", "3e-4",
                            PhiFlags("docs/data/partial-observability-paper/studies.log",
                                     "partial-observability-paper-cartpole-1res")),
                train_saved(f"{d}/cartpole-ppo", "--env", "CartPoleNoVel-v1", "--no-reservoir", "--learning-rate", "3e-4"),
                # LunarLander's `small` Φ* (2 reservoirs) at the paper's lr 1e-4 and 3M steps (host envs; resumes
                # from OUT.snapshot after a stop), and the `medium` Φ* at lr 3e-4, the model that met the target
                train_saved(f"{d}/lunarlander-small-2res", "--env", "LunarLanderNoVel-v3", "--reservoirs", 2,
                            "--learning-rate", "1e-4", "--env-workers", 0, "--timesteps", 3000000,
                            PhiFlags("docs/data/partial-observability-small/studies.log",
                                     "partial-observability-small-lunarlander-2res")),
                train_saved(f"{d}/lunarlander-medium-2res-lr3e-4", "--env", "LunarLanderNoVel-v3", "--reservoirs", 2,
                            "--learning-rate", "3e-4", "--env-workers", 0, "--timesteps", 3000000,
                            PhiFlags("docs/data/partial-observability-medium/studies.log",
                                     "partial-observability-medium-lunarlander-2res")),
                _evaluate(f"{d}/lunarlander.md",
                          *(f"{d}/lunarlander-{s}" for s in ("small-2res", "medium-2res-lr3e-4"))),
                _evaluate(f"{d}/pendulum.md", *(f"{d}/pendulum-{s}" for s in (
                    "default-phi-500u", "medium-500u", "500u-near-default", "500u-near-default-wide", "500u-lr1e-4",
                    "default-phi", "100u-near-default-wide", "lr1e-4", "ppo", "ppo-full-obs"))),
                _evaluate(f"{d}/cartpole.md", *(f"{d}/cartpole-{s}" for s in ("fitness-1m", "paper", "ppo"))))


def pendulum_rlzoo_ppo() -> Step:
    d, e = "docs/data/pendulum-rlzoo-ppo", EVAL
    trains = []
    for n in (500, 100):
        s = f"pendulum-{n}u-near-default-wide"
        trains += [train_saved(f"{d}/evolved-{n}u", "--env", "PendulumNoVel-v1", "--units", n, ZOO,
                               PhiFlags(f"docs/data/{s}/studies.log", s)),
                   train_saved(f"{d}/default-phi-{n}u", "--env", "PendulumNoVel-v1", "--units", n, DEFAULT_PHI, ZOO)]
    pairs = [("evolved 500u", f"{e}/{NEAR}"), ("default Φ 500u", f"{e}/pendulum-default-phi-500u"),
             ("evolved 100u", f"{e}/pendulum-100u-near-default-wide"), ("default Φ 100u", f"{e}/pendulum-default-phi"),
             ("masked", f"{e}/pendulum-ppo")]
    folder = {"evolved 500u": "evolved-500u", "default Φ 500u": "default-phi-500u", "evolved 100u": "evolved-100u",
              "default Φ 100u": "default-phi-100u", "masked": "ppo"}
    labels = [x for name, paper in pairs for x in (f"{name}, zoo={d}/{folder[name]}/summary.json",
                                                   f"{name}, paper={paper}/summary.json")]
    return step("pendulum_rlzoo_ppo", "C2", "the Pendulum target, its PPO settings: the reservoirs of "
                "deterministic_eval and PPO trained on the test seeds with rl-zoo's tuned RecurrentPPO settings but "
                "gSDE, paired with the paper's settings and evaluated on rl-zoo's metric",
                trains,
                train_saved(f"{d}/ppo", "--env", "PendulumNoVel-v1", "--no-reservoir", ZOO),
                train_saved(f"{d}/ppo-full-obs", "--env", "Pendulum-v1", "--no-reservoir", ZOO),
                compare(labels, f"full obs, zoo={d}/ppo-full-obs/summary.json",
                        [("--compare", f"{name}, zoo", f"{name}, paper") for name, _ in pairs],
                        "--compare", "evolved 500u, zoo", "default Φ 500u, zoo",
                        "--compare", "evolved 100u, zoo", "default Φ 100u, zoo", tee=f"{d}/summary.md"),
                compare(labels[:4], f"full obs, zoo={d}/ppo-full-obs/summary.json",
                        "--title", "rl-zoo's PPO settings (zoo) vs the paper's, 500 units", "--figure",
                        f"{d}/pendulum.png", show=False),
                _evaluate(f"{d}/evaluation.md", *(f"{d}/{r}" for r in (
                    "evolved-500u", "default-phi-500u", "evolved-100u", "default-phi-100u", "ppo", "ppo-full-obs"))))


def pendulum_normalize() -> Step:
    d, e, m = "docs/data/pendulum-normalize", EVAL, SEEDS_1010
    dev = ("--env", "PendulumNoVel-v1", "--units", 500, "--learning-rate", "1e-4", "--normalize", "--seeds", 10,
           "--first-seed", 1010, "--timesteps", 1000000, "--no-save-agents", "--quiet")
    return step("pendulum_normalize", "C2", "the Pendulum target, input normalization (rl-zoo's VecNormalize): the "
                "near-default Φ* and the default Φ at 500 units on the development seeds, then on the test seeds with "
                "PPO (masked and full obs) normalized too",
                train_once(f"{d}/dev/evolved", dev, NEAR_PHI),
                train_once(f"{d}/dev/default", dev, DEFAULT_PHI),
                Remove((f"{d}/dev/*/episodes.csv",)),
                compare(f"evolved, normalized={d}/dev/evolved/summary.json", f"evolved={m}/evolved/summary.json",
                        f"default Φ, normalized={d}/dev/default/summary.json", f"default Φ={m}/default/summary.json",
                        "--compare", "evolved, normalized", "evolved", "--compare", "default Φ, normalized",
                        "default Φ", "--title", "500 units, seeds 1010-1019", "--figure", f"{d}/dev/pendulum.png",
                        tee=f"{d}/dev/summary.md"),
                _four(d, ("--learning-rate", "1e-4", "--normalize"), ("--normalize",)),
                compare(f"evolved, normalized={d}/evolved-500u/summary.json", f"evolved={e}/{NEAR}/summary.json",
                        f"default Φ, normalized={d}/default-phi-500u/summary.json",
                        f"default Φ={e}/pendulum-default-phi-500u/summary.json",
                        f"masked, normalized={d}/ppo/summary.json", f"masked={e}/pendulum-ppo/summary.json",
                        f"full obs, normalized={d}/ppo-full-obs/summary.json",
                        "--compare", "evolved, normalized", "evolved",
                        "--compare", "default Φ, normalized", "default Φ", "--compare", "masked, normalized", "masked",
                        "--compare", "evolved, normalized", "default Φ, normalized",
                        "--title", "500 units, test seeds 1000-1009", "--figure", f"{d}/pendulum.png",
                        tee=f"{d}/summary.md"),
                _evaluate(f"{d}/evaluation.md", *(f"{d}/{r}" for r in FOUR)))


def pendulum_rlzoo_sde() -> Step:
    d, e, p, m = "docs/data/pendulum-rlzoo-sde", EVAL, "docs/data/pendulum-rlzoo-ppo", SEEDS_1010
    return step("pendulum_rlzoo_sde", "C2", "the Pendulum target, rl-zoo's recipe as far as ermrl follows it (its "
                "settings, --normalize, gSDE): PPO on Pendulum-v1 at 100k against rl-zoo's benchmark, then the "
                "near-default Φ* on the development and test seeds, the default Φ and PPO on the test seeds",
                train_once(f"{d}/ppo-pendulum-100k", "--env", "Pendulum-v1", "--no-reservoir", "--seeds", 10,
                           "--first-seed", 1000, "--timesteps", 100000, ZOO_SDE, "--quiet"),
                Remove((f"{d}/ppo-pendulum-100k/episodes.csv",)),
                _evaluate(f"{d}/ppo-pendulum-100k/evaluation.md", f"{d}/ppo-pendulum-100k"),
                train_once(f"{d}/dev/evolved", "--env", "PendulumNoVel-v1", "--units", 500, ZOO_SDE, "--normalize",
                           NEAR_PHI, "--seeds", 10, "--first-seed", 1010, "--timesteps", 1000000, "--no-save-agents",
                           "--quiet"),
                Remove((f"{d}/dev/evolved/episodes.csv",)),
                _four(d, (*ZOO_SDE, "--normalize"), (*ZOO_SDE, "--normalize")),
                compare(f"evolved, zoo + gSDE={d}/dev/evolved/summary.json", f"evolved, paper={m}/evolved/summary.json",
                        "--compare", "evolved, zoo + gSDE", "evolved, paper", "--title", "500 units, seeds 1010-1019",
                        tee=f"{d}/dev-summary.md"),
                compare(f"evolved, zoo + gSDE={d}/evolved-500u/summary.json", f"evolved, paper={e}/{NEAR}/summary.json",
                        f"evolved, zoo={p}/evolved-500u/summary.json",
                        f"default Φ, zoo + gSDE={d}/default-phi-500u/summary.json",
                        f"default Φ, paper={e}/pendulum-default-phi-500u/summary.json",
                        f"masked, zoo + gSDE={d}/ppo/summary.json",
                        f"full obs, zoo + gSDE={d}/ppo-full-obs/summary.json",
                        "--compare", "evolved, zoo + gSDE", "evolved, paper", "--compare", "evolved, zoo + gSDE",
                        "evolved, zoo", "--compare", "default Φ, zoo + gSDE", "default Φ, paper",
                        "--title", "rl-zoo + normalize + gSDE, 500 units", "--figure", f"{d}/pendulum.png",
                        tee=f"{d}/summary.md"),
                _evaluate(f"{d}/evaluation.md", *(f"{d}/{r}" for r in FOUR)))


def pendulum_rlzoo_policy() -> Step:
    d, e, z, m = "docs/data/pendulum-rlzoo-policy", EVAL, "docs/data/pendulum-rlzoo-sde", SEEDS_1010
    flags = {"zoo": (*RLZOO_PENDULUM, *RLZOO_POLICY), "paper": ("--learning-rate", "1e-4", *RLZOO_POLICY)}
    net = ("--env", "PendulumNoVel-v1", "--units", 500)
    return step("pendulum_rlzoo_policy", "C2", "the Pendulum target, rl-zoo's policy (64 units, ReLU, no orthogonal "
                "init) with rl-zoo's recipe (zoo) and the paper's settings (paper): the near-default Φ* on the "
                "development then the test seeds, the default Φ on the test seeds, then the default Φ confirmed on "
                "20 more seeds",
                [_dev(f"{d}/dev/evolved-{v}", net, f, NEAR_PHI) for v, f in flags.items()],
                compare(f"evolved, zoo policy={d}/dev/evolved-zoo/summary.json",
                        f"evolved, paper + zoo policy={d}/dev/evolved-paper/summary.json",
                        f"evolved, paper={m}/evolved/summary.json", f"evolved, zoo + gSDE={z}/dev/evolved/summary.json",
                        "--compare", "evolved, zoo policy", "evolved, zoo + gSDE",
                        "--compare", "evolved, paper + zoo policy", "evolved, paper",
                        "--title", "500 units, seeds 1010-1019", "--figure", f"{d}/dev/pendulum.png",
                        tee=f"{d}/dev/summary.md"),
                [(train_saved(f"{d}/evolved-{v}", net, f, NEAR_PHI),
                  train_saved(f"{d}/default-phi-{v}", net, DEFAULT_PHI, f)) for v, f in flags.items()],
                compare(f"evolved, zoo policy={d}/evolved-zoo/summary.json",
                        f"evolved, paper + zoo policy={d}/evolved-paper/summary.json",
                        f"evolved, paper={e}/{NEAR}/summary.json", f"evolved, zoo + gSDE={z}/evolved-500u/summary.json",
                        f"default Φ, zoo policy={d}/default-phi-zoo/summary.json",
                        f"default Φ, paper + zoo policy={d}/default-phi-paper/summary.json",
                        f"default Φ, paper={e}/pendulum-default-phi-500u/summary.json",
                        "--compare", "evolved, zoo policy", "evolved, zoo + gSDE",
                        "--compare", "evolved, paper + zoo policy", "evolved, paper",
                        "--compare", "default Φ, zoo policy", "default Φ, paper",
                        "--compare", "default Φ, paper + zoo policy", "default Φ, paper",
                        "--title", "rl-zoo's policy, 500 units, test seeds", "--figure", f"{d}/pendulum.png",
                        tee=f"{d}/summary.md"),
                _evaluate(f"{d}/evaluation.md", *(f"{d}/{r}" for r in ("evolved-zoo", "evolved-paper",
                                                                       "default-phi-zoo", "default-phi-paper"))),
                # the default Φ with rl-zoo's recipe on the development seeds and on 10 seeds never used before, so
                # that the pick among the configurations tried on the test seeds is checked on seeds it was not
                # picked on
                [(train_once(f"{d}/confirm/default-phi-zoo-{first}", net, DEFAULT_PHI, flags["zoo"], "--seeds", 10,
                             "--first-seed", first, "--timesteps", 1000000, "--no-save-agents", "--quiet"),
                  Remove((f"{d}/confirm/default-phi-zoo-{first}/episodes.csv",))) for first in (1010, 1020)],
                compare(f"default Φ, zoo policy, 1000-1009={d}/default-phi-zoo/summary.json",
                        f"default Φ, zoo policy, 1000-1029={d}/default-phi-zoo/summary.json,"
                        f"{d}/confirm/default-phi-zoo-1010/summary.json,{d}/confirm/default-phi-zoo-1020/summary.json",
                        f"default Φ, zoo policy, 1010-1019={d}/confirm/default-phi-zoo-1010/summary.json",
                        f"default Φ, zoo policy, 1020-1029={d}/confirm/default-phi-zoo-1020/summary.json",
                        f"default Φ, paper, 1000-1009={e}/pendulum-default-phi-500u/summary.json",
                        "--title", "default Φ, 500 units, rl-zoo's recipe, three seed sets",
                        "--figure", f"{d}/confirm/pendulum.png", tee=f"{d}/confirm/summary.md"))


def pendulum_rlzoo_evolve() -> Step:
    d, s, p = "docs/data/pendulum-rlzoo-evolve", "pendulum-500u-rlzoo", "docs/data/pendulum-rlzoo-policy"
    zoo, phi = (*RLZOO_PENDULUM, *RLZOO_POLICY), PhiFlags(f"{d}/studies.log", s)
    where = ("--study", s, "--storage", f"{d}/studies.log", "--out", f"runs/{s}")
    return step("pendulum_rlzoo_evolve", "C2", "the Pendulum target, ER-MRL under rl-zoo's recipe: Φ evolved with it "
                "(CMA-ES near the default Φ, 30 trials × 3 seeds × 300k, new seeds each generation), top 3 on 5 "
                "seeds, the Φ* on the test seeds against the default Φ, then on the development seeds",
                MakeDirs(d),
                ermrl("evolve", "--env", "PendulumNoVel-v1", "--units", 500, "--reservoirs", 1, "--fixed-iss", "1.0",
                      "--trials", 30, "--seeds", 3, "--popsize", 10, "--seed-schedule", "generation", "--timesteps",
                      300000, zoo, "--min-sr", "0.1", "--max-sr", "10", "--min-leak-rate", "0.1", "--max-leak-rate",
                      "1.0", where, "--quiet"),
                ermrl("select", where, "--top", 3, "--seeds", 5, "--quiet", tee=f"{d}/selection.txt"),
                train_saved(f"{d}/evolved", "--env", "PendulumNoVel-v1", "--units", 500, zoo, phi),
                compare(f"evolved under rl-zoo's recipe={d}/evolved/summary.json",
                        f"default Φ, rl-zoo's recipe={p}/default-phi-zoo/summary.json",
                        f"evolved under the paper's, rl-zoo's recipe={p}/evolved-zoo/summary.json",
                        "--compare", "evolved under rl-zoo's recipe", "default Φ, rl-zoo's recipe",
                        "--compare", "evolved under rl-zoo's recipe", "evolved under the paper's, rl-zoo's recipe",
                        "--title", "500 units, rl-zoo's recipe, test seeds", "--figure", f"{d}/pendulum.png",
                        tee=f"{d}/summary.md"),
                _evaluate(f"{d}/evaluation.md", f"{d}/evolved"),
                _dev(f"{d}/dev/evolved", "--env", "PendulumNoVel-v1", "--units", 500, zoo, phi),
                compare(f"evolved under rl-zoo's recipe, 1010-1019={d}/dev/evolved/summary.json",
                        f"evolved under rl-zoo's recipe, 1000-1019={d}/evolved/summary.json,"
                        f"{d}/dev/evolved/summary.json",
                        f"default Φ, rl-zoo's recipe, 1010-1019={p}/confirm/default-phi-zoo-1010/summary.json",
                        "--compare", "evolved under rl-zoo's recipe, 1010-1019",
                        "default Φ, rl-zoo's recipe, 1010-1019",
                        "--title", "500 units, rl-zoo's recipe, seeds 1010-1019", tee=f"{d}/dev/summary.md"))


def pendulum_rlzoo_lstm() -> Step:
    d = "docs/data/pendulum-rlzoo-lstm"
    zoo = ("--env", "PendulumNoVel-v1", "--model", "lstm", RLZOO_PENDULUM, "--batch-size", "128", "--lstm-seq-len",
           "128", RLZOO_POLICY)
    return step("pendulum_rlzoo_lstm", "C5", "the Pendulum target's source: rl-zoo's own PendulumNoVel agent "
                "(RecurrentPPO with its tuned settings) trained by ermrl's PPO-LSTM on the test seeds at 100k and 1M, "
                "scored the paper's way and rl-zoo's",
                [(train_once(f"{d}/lstm-{t}", zoo, "--seeds", 10, "--first-seed", 1000, "--timesteps", t, "--quiet"),
                  Remove((f"{d}/lstm-{t}/episodes.csv",))) for t in (100000, 1000000)],
                _evaluate(f"{d}/evaluation.md", f"{d}/lstm-100000", f"{d}/lstm-1000000"))


def recurrent_vs_ermrl() -> Step:
    return step("recurrent_vs_ermrl", "C5", "C5: PPO-LSTM against ER-MRL (default Φ, lr 1e-4 and 3e-4) on the masked "
                "classic-control tasks, 10 seeds × 1M each (resumes: a run saved under docs/data/recurrent_vs_ermrl/ "
                "is skipped)", python("paper/recurrent_vs_ermrl.py", "--timesteps", 1000000))
