"""The reproduction's steps of H2 and H3 (locomotion, rhythm and generalization, C7-C13 and C16): the MuJoCo
studies at `small` and `converged`, the FFT of their agents, the HP maps (as data, see :mod:`.actions`)."""

from __future__ import annotations

from ermrl.experiments.reproduction.actions import (
    NOT_SAVED, TEST10, Collect, Exists, MakeDirs, Missing, Run, Step, compare, ermrl, experiment, made, python,
    step,
)

SMALL = "docs/data/locomotion-small"
TRIO = ("ant", "halfcheetah", "swimmer")


def steps() -> list[Step]:
    return [h2(), c8(), fft(), fft_early(), h3(), humanoid(), c13(), c16(), hpmap(), c11(), c11_2res(),
            h2_converged(), h2_converged_interim(), h3_converged(), h3_converged_interim(), c8_converged()]


def h2() -> Step:
    return step("h2", "C7", "H2: Ant, HalfCheetah, Swimmer with 2 reservoirs, small evolution, test 10 × 1M against "
                "PPO",
                experiment("locomotion", "small", "--only", "ant-2res", "halfcheetah-2res", "swimmer-2res", TEST10))


def h2_converged() -> Step:
    actions = [(experiment("locomotion", "converged", "--only", f"{s}-2res", TEST10),
                _against_small(f"{CONVERGED}/{s}-2res", f"{CONVERGED}/{s}-2res/test/summary.json",
                               f"{SMALL}/{s}-2res/test/summary.json"))
               for s in ("halfcheetah", "swimmer", "ant")]
    return step("h2_converged", "C7", "C7 at --scale converged: each evolution until CMA-ES has converged (at most 900 "
                "trials), then selection and 10 × 1M against PPO and the small study's Φ*; one study at a time, "
                "HalfCheetah first", actions)


def _against_small(folder: str, summary: str, small_summary: str, label: str = "converged study",
                   title: str = "Φ* of the converged and the small study") -> Run:
    """``ermrl compare`` of a converged study's test phase (``summary``, named ``label``) against its PPO and the
    small study's Φ* on the same seeds, into ``folder/comparison.{md,png}``."""
    return compare(f"{label}={summary}", f"small study={small_summary}",
                   "--compare", label, "PPO (same observation)", "--compare", label, "small study",
                   "--title", title, "--figure", f"{folder}/comparison.png", tee=f"{folder}/comparison.md")


CONVERGED = "docs/data/locomotion-converged"
SO_FAR = {"halfcheetah": 19, "ant": 19, "swimmer": 19}
"""{task: the last generation of its converged-scale C7 study that ``h2_converged_interim`` selects and tests
from}: a study ahead of its end, while it runs on (add a task once its study has about 20 generations)."""


def h2_converged_interim() -> Step:
    actions = [_interim(f"locomotion-converged-{task}-2res", CONVERGED, f"{task}-gen{generation}", generation,
                        f"{SMALL}/{task}-2res/test/summary.json") for task, generation in SO_FAR.items()]
    so_far = ", ".join(f"{task} after generation {generation}" for task, generation in SO_FAR.items())
    return step("h2_converged_interim", "C7", f"h2_converged's studies ahead of their end ({so_far}): each "
                "study's trials up to a generation copied aside (paper/study_so_far.py), the top 5 re-evaluated "
                "on 5 seeds, Φ* tested 10 × 1M against PPO (from the store), and compared with the small study's "
                "Φ*", actions)


GENERALIZATION = "docs/data/generalization-morphology-converged"
GENERALIZATION_SO_FAR = {"ant": 21}
"""{held-out task: the last generation of its converged-scale C10 study (``to-TASK``) that ``h3_converged_interim``
selects and tests from}, as :data:`SO_FAR` for C7."""
ENV_IDS = {"ant": "Ant-v5", "halfcheetah": "HalfCheetah-v5", "swimmer": "Swimmer-v5"}
"""The env of each task of :data:`TRIO`."""


def h3_converged_interim() -> Step:
    actions = [_interim(f"generalization-morphology-converged-to-{task}", GENERALIZATION, f"to-{task}-gen{generation}",
                        generation, f"docs/data/generalization-morphology-small/to-{task}/test-{ENV_IDS[task]}/"
                        "summary.json", ENV_IDS[task]) for task, generation in GENERALIZATION_SO_FAR.items()]
    so_far = ", ".join(f"to-{task} after generation {g}" for task, g in GENERALIZATION_SO_FAR.items())
    return step("h3_converged_interim", "C10", f"h3_converged's studies ahead of their end ({so_far}): as "
                "h2_converged_interim, the top 5 re-evaluated on 5 seeds on the two evolution envs, Φ* tested "
                "10 × 1M on the held-out env against PPO (from the store) and the small study's Φ*", actions)


def _interim(study: str, journal_dir: str, name: str, generation: int, small_summary: str,
             test_env: str | None = None) -> tuple:
    """The actions that select and test ``study`` as it stood after ``generation``, in ``journal_dir/name``: its
    trials copied aside, the top 5 on 5 seeds, Φ* 10 × 1M (on ``test_env``, else the evolution's env) against PPO
    and the small study's Φ* (``small_summary``)."""
    d = f"{journal_dir}/{name}"
    where = ("--study", study, "--storage", f"{d}/studies.log")
    test = f"{d}/test-{test_env}" if test_env else f"{d}/test"
    return (
        python("paper/study_so_far.py", "--study", study, "--storage", f"journal:{journal_dir}/studies.log",
               "--generation", generation, "--to", f"journal:{d}/studies.log", skip_if=made(f"{d}/studies.log")),
        ermrl("select", where, "--out", f"runs/{study}-gen{generation}", "--top", 5, "--seeds", 5, "--quiet"),
        ermrl("test", where, "--out", d, *(("--env", test_env) if test_env else ()), "--seeds", 10, "--timesteps",
              1000000, "--auc-steps", 300000, "--baseline-store", "docs/data/baseline-models", NOT_SAVED,
              skip_if=made(f"{test}/summary.json")),
        _against_small(d, f"{test}/summary.json", small_summary, f"converged study, generation {generation}",
                       f"Φ* after {generation + 1} CMA-ES generations"))


def h3_converged() -> Step:
    held_out = [(t, ENV_IDS[t]) for t in TRIO]
    return step("h3_converged", "C10", "C10 at --scale converged: the three generalization groups, each Φ* tested on "
                "its held-out env against PPO and the small study's Φ*",
                experiment("generalization-morphology", "converged", TEST10),
                [_against_small(f"{GENERALIZATION}/to-{t}", f"{GENERALIZATION}/to-{t}/test-{env}/summary.json",
                                f"docs/data/generalization-morphology-small/to-{t}/test-{env}/summary.json")
                 for t, env in held_out])


def c8_converged() -> Step:
    return step("c8_converged", "C8", "C8 at --scale converged: Hopper and Walker2d",
                experiment("locomotion", "converged", "--only", "hopper-2res", "walker2d-2res", TEST10))


def c8() -> Step:
    return step("c8", "C8", "C8: Hopper and Walker2d, where the paper saw no gain: small evolution, test 10 × 1M "
                "against PPO", experiment("locomotion", "small", "--only", "hopper-2res", "walker2d-2res", TEST10))


def fft() -> Step:
    actions = []
    for s in TRIO:
        t = f"runs/experiments/locomotion-small/{s}-2res/test/agents"
        gone = (Missing(t), Exists(f"{SMALL}/fft/{s}.json"))  # done, and its agents are gone
        actions += [MakeDirs(f"{SMALL}/fft", skip_if=gone),
                    ermrl("analyze", "fft", f"{t}/ermrl", f"{t}/ppo", "--max-steps", 1000, "--out",
                          f"{SMALL}/fft/{s}.png", skip_if=gone)]
    return step("fft", "C9", "H2: the rhythm of the test phases' ER-MRL and PPO agents", actions)


def fft_early() -> Step:
    actions = []
    for s in TRIO:
        t = f"runs/experiments/locomotion-small-early/{s}/test/agents"
        actions += [ermrl("test", "--study", f"locomotion-small-{s}-2res", "--storage", f"{SMALL}/studies.log",
                          "--out", f"runs/experiments/locomotion-small-early/{s}", "--seeds", 5, "--timesteps", 100000),
                    ermrl("analyze", "fft", f"{t}/ermrl", f"{t}/ppo", "--max-steps", 1000, "--out",
                          f"{SMALL}/fft/{s}_100k.png")]
    return step("fft_early", "C9", "H2, C9 (\"very early in the learning process\"): Φ* and PPO trained 5 seeds × "
                "100k, then the FFT; the 100k test phases' summaries and curves collected",
                actions, Collect("locomotion-small-early"))


def h3() -> Step:
    return step("h3", "C10", "H3: evolved on two of Ant/HalfCheetah/Swimmer, tested on the third (10 × 1M); the "
                "studies evolving on Ant get 200k-step trials (the registry's floor)",
                experiment("generalization-morphology", "small", TEST10))


def humanoid() -> Step:
    return step("humanoid", "C12", "H3 / C12: Humanoid <-> HumanoidStandup, small evolution, test 10 seeds × 200k "
                "(the PPO baselines are C13's, from the store)",
                experiment("generalization-humanoid", "small", "--test-seeds", 10))


def c13() -> Step:
    g = "docs/data/generalization-humanoid-small"
    actions = [experiment("locomotion", "small", "--only", "humanoid-2res", "humanoidstandup-2res", "--test-seeds", 10)]
    # each Φ* against PPO and against C12's Φ* evolved on the other task, on the same 10 test seeds
    for env, study, other, source in (("Humanoid-v5", "humanoid", "standup-to-humanoid", "HumanoidStandup"),
                                      ("HumanoidStandup-v5", "humanoidstandup", "humanoid-to-standup", "Humanoid")):
        own, theirs = f"evolved on {env.removesuffix('-v5')}", f"evolved on {source} (C12)"
        actions.append(compare(f"{own}={SMALL}/{study}-2res/test/summary.json",
                               f"{theirs}={g}/{other}/test-{env}/summary.json",
                               "--compare", own, "PPO (same observation)", "--compare", own, theirs,
                               "--title", "2 × 100 units for 348 obs dims, small, 10 × 200k",
                               "--figure", f"{SMALL}/c13-{study}.png", tee=f"{SMALL}/c13-{study}.md"))
    return step("c13", "C13", "C13: Humanoid and HumanoidStandup read through 2 reservoirs of 100 units, small "
                "evolution on the task itself, test 10 × 200k against PPO and C12's Φ*", actions)


def c16() -> Step:
    d = "docs/data/reservoir-count-small"
    k2 = "docs/data/generalization-morphology-small/to-ant/test-Ant-v5/summary.json"
    return step("c16", "C16", "C16: K = 3 (and K = 1) reservoirs in the to-ant group (evolved on HalfCheetah and "
                "Swimmer, tested on Ant 10 × 1M), against H3's K = 2: small evolutions",
                experiment("reservoir-count", "small", "--only", "to-ant-3res", TEST10),
                experiment("reservoir-count", "small", "--only", "to-ant-1res", TEST10),
                compare(f"1 reservoir={d}/to-ant-1res/test-Ant-v5/summary.json", f"2 reservoirs={k2}",
                        f"3 reservoirs={d}/to-ant-3res/test-Ant-v5/summary.json",
                        "--compare", "3 reservoirs", "2 reservoirs", "--compare", "1 reservoir", "2 reservoirs",
                        "--figure", f"{d}/curves.png", tee=f"{d}/summary.md"))


def hpmap() -> Step:
    return step("hpmap", "C11", "H3 / appendix: the top Φ of the locomotion studies on sr × lr",
                ermrl("analyze", "hp-map", *(f"locomotion-small-{s}-2res" for s in TRIO), "--storage",
                      f"{SMALL}/studies.log", "--out", f"{SMALL}/hp_map.png"))


def _evolve_c11(env: str, reservoirs: int, d: str) -> tuple:
    name = f"c11-{env.removesuffix('-v5').lower()}-{reservoirs}res"
    return ermrl("evolve", "--env", env, "--reservoirs", reservoirs, "--trials", 80, "--seeds", 2, "--timesteps",
                 50000, "--study", name, "--storage", f"{d}/studies.log", "--out", f"runs/{name}")


def c11() -> Step:
    d = "docs/data/c11-hp-map"
    studies = [f"c11-{s}-1res" for s in TRIO]
    return step("c11", "C11", "C11: where each env's best Φ lie once CMA-ES has room to move: 1 reservoir, 80 trials "
                "× 2 seeds × 50k per env, the HP map of the top 10 and 30, then Ant from another start",
                [_evolve_c11(env, 1, d) for env in ("Ant-v5", "HalfCheetah-v5", "Swimmer-v5")],
                [ermrl("analyze", "hp-map", *studies, "--storage", f"{d}/studies.log", "--top", top, "--out",
                       f"{d}/hp_map_top{top}.png") for top in (10, 30)],
                # Ant again from another start: the sampler's seed 1 draws other first Φ (its own journal)
                ermrl("evolve", "--env", "Ant-v5", "--reservoirs", 1, "--trials", 56, "--seeds", 2, "--timesteps",
                      50000, "--sampler-seed", 1, "--study", "c11-ant-1res-sampler1", "--storage",
                      f"{d}/sampler1.log", "--out", "runs/c11-ant-1res-sampler1"),
                ermrl("analyze", "hp-map", "c11-ant-1res-sampler1", "--storage", f"{d}/sampler1.log", "--top", 30,
                      "--out", f"{d}/sampler1_top30.png"))


def c11_2res() -> Step:
    d = "docs/data/c11-hp-map"
    studies = [f"c11-{s}-{k}res" for s in TRIO for k in (1, 2)]
    return step("c11_2res", "C11", "C11's right panel: the same evolutions with 2 reservoirs (6 dims, popsize 9) into "
                "the same journal, then the HP map of the six studies, 1 and 2 reservoirs side by side",
                [_evolve_c11(env, 2, d) for env in ("HalfCheetah-v5", "Swimmer-v5", "Ant-v5")],
                [ermrl("analyze", "hp-map", *studies, "--storage", f"{d}/studies.log", "--top", top, "--out",
                       f"{d}/hp_map_1and2res_top{top}.png") for top in (10, 30)])
