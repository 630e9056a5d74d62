"""The reproduction's steps of H1 (partial observability, C1-C6): the masked CartPole, Pendulum and LunarLander
studies, the probe of their Φ*, the peer check and the evolution's seed schedule (as data, see :mod:`.actions`)."""

from __future__ import annotations

from ermrl.experiments.reproduction.actions import (
    DEFAULT_PHI, NOT_SAVED, STORE, TEST10, TEST_FILES, CopyFiles, FirstOf, MakeDirs, Missing, PhiFlags, Step, StopIf,
    compare, done, ermrl, experiment, made, python, reference, step, train_once,
)

PO = "partial-observability"


def steps() -> list[Step]:
    return [cartpole(), pendulum(), pendulum_medium(), pendulum_paper(), lunarlander(), lunarlander_1res(),
            lunarlander_medium(), lunarlander_lr3e4(), probe(), peer(), seed_schedule(), seed_schedule_paper(),
            fitness_1m(), c3_converged()]


def cartpole() -> Step:
    return step("cartpole", "C1 C2 C6", "H1: CartPoleNoVel at the paper's scale (900 trials), selection, test 10 × 1M "
                "at 3 learning rates", experiment(PO, "paper", "--only", "cartpole-1res"))


def pendulum() -> Step:
    return step("pendulum", "C1 C2 C6", "H1: PendulumNoVel, small evolution, test 10 × 1M",
                experiment(PO, "small", "--only", "pendulum-1res", TEST10))


def pendulum_medium() -> Step:
    d = "docs/data/partial-observability-medium/default-phi"
    return step("pendulum_medium", "C2 C6", "H1 at the paper's per-trial budget (small's 50k-step trials select "
                "noise there), then the default Φ at the evolution's budget on its seeds and the selection's",
                experiment(PO, "medium", "--only", "pendulum-1res"),
                train_once(f"{d}/seeds0to2", "--env", "PendulumNoVel-v1", "--seeds", 3, "--timesteps", 300000,
                           NOT_SAVED),
                train_once(f"{d}/seeds2000to2004", "--env", "PendulumNoVel-v1", "--seeds", 5, "--first-seed", 2000,
                           "--timesteps", 300000, NOT_SAVED))


def pendulum_paper() -> Step:
    return step("pendulum_paper", "C2", "H1: PendulumNoVel at the paper's scale (900 trials × 3 seeds × 300k, "
                "resumes): medium's 60 trials never reached the default Φ's region",
                experiment(PO, "paper", "--only", "pendulum-1res"))


def lunarlander() -> Step:
    return step("lunarlander", "C1 C2 C3", "H1: LunarLanderNoVel with 2 reservoirs, small evolution, test 10 × 3M at "
                "lr 1e-4 (a model resumes from its snapshot; all 10 agents in the main process)",
                experiment(PO, "small", "--only", "lunarlander-2res", "--test-seeds", 10, "--test-timesteps", 3000000,
                           "--test-learning-rates", "1e-4", "--env-workers", 0))


def c3_converged() -> Step:
    return step("c3_converged", "C3", "C3 at --scale converged: LunarLanderNoVel with 1 and 2 reservoirs, tested "
                "10 × 3M",
                experiment(PO, "converged", "--only", "lunarlander-1res", "lunarlander-2res", "--test-seeds", 10))


def lunarlander_medium() -> Step:
    return step("lunarlander_medium", "C2", "the LunarLander target at the paper's per-trial budget (60 trials × 3 "
                "seeds × 300k), selection, test 10 × 3M at lr 1e-4 (PPO's baselines from the store)",
                experiment(PO, "medium", "--only", "lunarlander-2res", "--test-learning-rates", "1e-4", "--env-workers", 0))


def lunarlander_lr3e4() -> Step:
    d = "docs/data/partial-observability-medium/lunarlander-2res"
    phi = PhiFlags("docs/data/partial-observability-medium/studies.log",
                   "partial-observability-medium-lunarlander-2res")
    return step("lunarlander_lr3e4", "C2 C6", "the LunarLander target's miss: the medium Φ* (evolved at lr 3e-4, "
                "tested at 1e-4) on the same test seeds at 3e-4, ER-MRL only, paired with its 1e-4 test",
                train_once(f"{d}/ermrl-lr3e-4", "--env", "LunarLanderNoVel-v3", phi, "--reservoirs", 2, "--seeds", 10,
                           "--first-seed", 1000, "--timesteps", 3000000, "--learning-rate", "3e-4", "--env-workers", 0,
                           NOT_SAVED),
                compare(f"medium Φ*, lr 1e-4={d}/test/summary.json",
                        f"medium Φ*, lr 3e-4={d}/ermrl-lr3e-4/summary.json",
                        "small Φ*, lr 1e-4=docs/data/partial-observability-small/lunarlander-2res/test/summary.json",
                        "--compare", "medium Φ*, lr 3e-4", "medium Φ*, lr 1e-4",
                        "--compare", "medium Φ*, lr 3e-4", "small Φ*, lr 1e-4",
                        "--compare", "medium Φ*, lr 3e-4", "PPO (full observation)",
                        "--title", "evolved Φ* at PPO lr 1e-4 and 3e-4, the same seeds",
                        "--figure", f"{d}/lr3e-4-vs-1e-4.png", tee=f"{d}/lr3e-4-vs-1e-4.md"))


def lunarlander_1res() -> Step:
    d, r = "docs/data/c3-lunarlander", "runs/c3-lunarlander"
    kept = "partial-observability-small/lunarlander-2res/test.partial/ermrl.npz"
    # the 2-reservoir ER-MRL model: its test phase's summary, else the model kept while the PPO baselines train,
    # else that model stashed at a stop
    two = ("docs/data/partial-observability-small/lunarlander-2res/test/summary.json", f"runs/experiments/{kept}",
           f"docs/data/{kept}")
    return step("lunarlander_1res", "C3", "C3, 1 reservoir against 2: the lunarlander study's small evolution and "
                "selection with one reservoir, its Φ* on the test seeds (3M, lr 1e-4), then compared",
                ermrl("evolve", "--env", "LunarLanderNoVel-v3", "--reservoirs", 1, "--fixed-iss", "1.0", "--trials", 18,
                      "--seeds", 2, "--timesteps", 50000, "--env-workers", 0, "--study", "lunarlander-1res",
                      "--storage", f"{d}/studies.log", "--out", r, "--quiet"),
                ermrl("select", "--study", "lunarlander-1res", "--storage", f"{d}/studies.log", "--out", r, "--top", 3,
                      "--seeds", 3, "--quiet"),
                train_once(f"{d}/ermrl-1res", "--env", "LunarLanderNoVel-v3",
                           PhiFlags(f"{d}/studies.log", "lunarlander-1res"), "--seeds", 10, "--first-seed", 1000,
                           "--timesteps", 3000000, "--learning-rate", "1e-4", "--env-workers", 0, NOT_SAVED),
                StopIf(tuple(Missing(p) for p in two), "C3: the 2-reservoir ER-MRL model is not trained yet (step "
                       "lunarlander)"),
                python("paper/reservoir_count_summary.py", FirstOf(two), d, tee=f"{d}/summary.md"))


def probe() -> Step:
    runs = []
    for env, data, study, name in (("CartPoleNoVel-v1", "partial-observability-paper", "cartpole-1res", "cartpole"),
                                   ("PendulumNoVel-v1", "partial-observability-small", "pendulum-1res", "pendulum"),
                                   ("PendulumNoVel-v1", "partial-observability-medium", "pendulum-1res", "pendulum"),
                                   ("PendulumNoVel-v1", "partial-observability-paper", "pendulum-1res", "pendulum"),
                                   ("LunarLanderNoVel-v3", "partial-observability-small", "lunarlander-2res",
                                    "lunarlander")):
        # no Φ* yet while the study has no folder: its test phase (done or kept unfinished) comes after
        runs.append(ermrl("analyze", "probe", "--env", env, "--study", f"{data}-{study}", "--storage",
                          f"docs/data/{data}/studies.log", "--out", f"docs/data/{data}/probe/{name}.png",
                          skip_if=(Missing(f"docs/data/{data}/{study}"),)))
    # the studies of their own steps (fitness_1m, seed_schedule_paper), whose names are not EXPERIMENT-STUDY
    for env, data, study, name in (("CartPoleNoVel-v1", "fitness-1m", "cartpole-1res-fitness-1m", "cartpole"),
                                   ("PendulumNoVel-v1", "fitness-1m", "pendulum-1res-fitness-1m", "pendulum"),
                                   ("CartPoleNoVel-v1", "seed-schedule", "cartpole-1res-generation-900",
                                    "cartpole-generation-900")):
        runs.append(ermrl("analyze", "probe", "--env", env, "--study", study, "--storage",
                          f"docs/data/{data}/studies.log", "--out", f"docs/data/{data}/probe/{name}.png",
                          skip_if=(Missing(f"docs/data/{data}/studies.log"),)))
    return step("probe", "C4", "H1, C4: velocity R² of each H1 study's Φ*, against the default Φ and a memoryless "
                "one (1 reservoir)", runs)


def peer() -> Step:
    d = "docs/data/partial-observability-paper/peer"
    phi = PhiFlags("docs/data/partial-observability-paper/studies.log", "partial-observability-paper-cartpole-1res")
    pipeline = "benchmarks/reference_pipeline.py"
    actions: list = [MakeDirs(d)]
    for bias in ("bernoulli", "none"):  # 10 seeds in two parts (0-3, then 4-9); each part is skipped once it exists
        actions += [reference(pipeline, "--agents", 4, "--timesteps", 300000, "--procs", 2, phi, "--bias", bias,
                              "--json", f"{d}/reference-{bias}.json", skip_if=made(f"{d}/reference-{bias}.json")),
                    reference(pipeline, "--agents", 6, "--first-seed", 4, "--timesteps", 300000, "--procs", 2, phi,
                              "--bias", bias, "--json", f"{d}/reference-{bias}-4to9.json",
                              skip_if=made(f"{d}/reference-{bias}-4to9.json"))]
    # ermrl on the evolution's own seeds (0-3: 0, 1 and 2 scored the trial), then on 10 seeds no evolution used
    cartpole = ("--env", "CartPoleNoVel-v1", phi)
    actions += [train_once(f"{d}/ermrl-bernoulli", cartpole, "--seeds", 4, "--timesteps", 300000, "--no-save-agents"),
                train_once(f"{d}/ermrl-none-host", cartpole, "--seeds", 4, "--timesteps", 300000, "--bias", "none",
                           "--backend", "host", "--no-save-agents"),
                train_once(f"{d}/ermrl-bernoulli-fresh", cartpole, "--seeds", 10, "--first-seed", 1000, "--timesteps",
                           300000, "--no-save-agents"),
                train_once(f"{d}/ermrl-none-host-fresh", cartpole, "--seeds", 10, "--first-seed", 1000,
                           "--timesteps", 300000, "--bias", "none", "--backend", "host", "--no-save-agents")]
    # paired: SB3 on ermrl's reservoirs for 1000-1009, SB3 on ReservoirPy's for 10-19, ermrl's PPO on
    # ReservoirPy's for 0-29 (and on its own draws), then the paired table
    weights = f"{d}/reference-bernoulli-ermrl-weights-1000to1009.json"
    actions += [reference(pipeline, "--agents", 10, "--first-seed", 1000, "--timesteps", 300000, "--procs", 2, phi,
                          "--bias", "bernoulli", "--weights", "ermrl", "--json", weights, skip_if=made(weights)),
                reference(pipeline, "--agents", 10, "--first-seed", 10, "--timesteps", 300000, "--procs", 2, phi,
                          "--bias", "bernoulli", "--json", f"{d}/reference-bernoulli-10to19.json",
                          skip_if=made(f"{d}/reference-bernoulli-10to19.json")),
                reference("paper/peer_reservoir_draws.py", "--agents", 30, "--timesteps", 300000, phi, "--bias",
                          "bernoulli", "--json", f"{d}/ermrl-ppo-draws-0to29.json",
                          skip_if=made(f"{d}/ermrl-ppo-draws-0to29.json")),
                python("paper/peer_summary.py", d, tee=f"{d}/paired.md")]
    return step("peer", "C2", "peer agreement: the CartPole Φ* trained 10 × 300k by SB3 + ReservoirPy and by ermrl, "
                "then paired on the same reservoirs", actions)


def _evolve_select_test(study: str, d: str, r: str, tested: str, evolve: tuple, test: tuple) -> list:
    """``ermrl evolve`` and ``ermrl select`` (top 5 × 5 seeds) of ``study`` in ``d/studies.log``, run folder ``r``;
    then, until ``tested/summary.json`` exists, its test phase and the copy of its small files into ``tested``."""
    storage = ("--study", study, "--storage", f"{d}/studies.log", "--out", r)
    return [ermrl("evolve", evolve, storage, "--quiet"),
            ermrl("select", storage, "--top", 5, "--seeds", 5, "--quiet"),
            ermrl("test", storage, "--seeds", 10, "--timesteps", 1000000, test, "--quiet", skip_if=done(tested)),
            CopyFiles(f"{r}/test", tested, TEST_FILES, skip_if=done(tested))]


def seed_schedule() -> Step:
    d, actions = "docs/data/seed-schedule", []
    for s in ("generation", "fixed"):
        actions += _evolve_select_test(f"cartpole-1res-{s}", d, f"runs/seed-schedule/{s}", f"{d}/{s}/test",
                                       ("--env", "CartPoleNoVel-v1", "--trials", 60, "--seeds", 3, "--timesteps",
                                        300000, "--fixed-iss", "1.0", "--seed-schedule", s), ())
    return step("seed_schedule", "C2", "C2's likely cause, the evolution's fixed seeds: CartPoleNoVel, 60 trials with "
                "seeds 0-2 for every trial against new seeds each generation; each selected and tested 10 × 1M",
                actions)


def seed_schedule_paper() -> Step:
    d = "docs/data/seed-schedule"
    return step("seed_schedule_paper", "C2", "C2 / the CartPole target: the paper-scale CartPoleNoVel study (900 "
                "trials × 3 seeds × 300k) with new seeds each generation, selected (top 5 × 5) and tested 10 × 1M",
                _evolve_select_test("cartpole-1res-generation-900", d, "runs/seed-schedule/generation-900",
                                    f"{d}/generation-900/test",
                                    ("--env", "CartPoleNoVel-v1", "--trials", 900, "--seeds", 3, "--timesteps", 300000,
                                     "--fixed-iss", "1.0", "--seed-schedule", "generation"), ()))


def fitness_1m() -> Step:
    d, actions = "docs/data/fitness-1m", []
    for env, s in (("CartPoleNoVel-v1", "cartpole"), ("PendulumNoVel-v1", "pendulum")):
        actions += _evolve_select_test(f"{s}-1res-fitness-1m", d, f"runs/fitness-1m/{s}", f"{d}/{s}/test",
                                       ("--env", env, "--trials", 60, "--seeds", 3, "--timesteps", 1000000,
                                        "--fixed-iss", "1.0", "--learning-rate", "1e-4"),
                                       ("--learning-rate", "1e-4", "--baseline-learning-rate", "3e-4", "--baseline-store", STORE))
    # the default Φ (sr 0.95, lr 0.5, iss 1), not evolved, on the same test seeds: what the Pendulum evolutions miss
    actions.append(train_once(f"{d}/default-phi-pendulum", "--env", "PendulumNoVel-v1", DEFAULT_PHI, "--seeds", 10,
                              "--first-seed", 1000, "--timesteps", 1000000, "--learning-rate", "1e-4", NOT_SAVED))
    return step("fitness_1m", "C2", "the CartPole and Pendulum targets: evolutions whose trials train 1M steps (the "
                "test budget) at lr 1e-4, selection (top 5 × 5 × 1M), test 10 × 1M; then the default Φ on Pendulum",
                actions)
