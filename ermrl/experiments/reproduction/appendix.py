"""The reproduction's steps of the appendix's reservoir variants (C14-C17): sizes, observed units, the probe at
those sizes and ReservoirPy's other hyperparameters (as data, see :mod:`.actions`)."""

from __future__ import annotations

from ermrl.experiments.reproduction.actions import (
    DEFAULT_PHI, NOT_SAVED, TEST10, PhiFlags, Step, compare, ermrl, experiment, made, python, step, train_once,
)

SIZES = (25, 50, 100, 200, 500, 1000)


def steps() -> list[Step]:
    return [observed_units(), observed_units_lr3e4(), sizes(), sizes_medium(), sizes_medium_lr3e4(), probe_sizes(),
            other_hps()]


def observed_units() -> Step:
    d = "docs/data/observed-units-small"
    return step("observed_units", "C15", "C15: CartPoleNoVel reading 100 of 100, 1000 of 1000 and 100 of 1000 units; "
                "small evolutions (iss fixed at 1.0), each Φ* tested 10 × 1M against PPO",
                experiment("observed-units", "small", TEST10),
                compare(f"100 of 100={d}/100-of-100/test/summary.json",
                        f"1000 of 1000={d}/1000-of-1000/test/summary.json",
                        f"100 of 1000={d}/100-of-1000/test/summary.json", "--compare", "100 of 100", "1000 of 1000",
                        "--compare", "100 of 1000", "1000 of 1000", "--compare", "100 of 1000", "100 of 100",
                        "--figure", f"{d}/curves.png", tee=f"{d}/summary.md"))


def observed_units_lr3e4() -> Step:
    return at_lr3e4("observed_units_lr3e4", "C6 C15", "C15 / the CartPole target: the 1000-of-1000 Φ* (evolved and "
                    "selected at lr 3e-4, tested at 1e-4) on the same test seeds at 3e-4, ER-MRL only, paired with "
                    "its 1e-4 test phase", "docs/data/observed-units-small", "1000-of-1000", "CartPoleNoVel-v1", 1000,
                    "1000 of 1000")


def at_lr3e4(name: str, claims: str, description: str, d: str, study: str, env: str, units: int, label: str) -> Step:
    """A step that trains study EXPERIMENT-STUDY's Φ* (journal ``d/studies.log``, EXPERIMENT the name of ``d``)
    on the test seeds at PPO lr 3e-4, the rate it was evolved and selected at, ER-MRL only, into
    ``d/STUDY/ermrl-lr3e-4``, and pairs it with its test phase at 1e-4 (``d/STUDY/lr3e-4-vs-1e-4.md``)."""
    f = f"{d}/{study}"
    return step(name, claims, description,
                train_once(f"{f}/ermrl-lr3e-4", "--env", env,
                           PhiFlags(f"{d}/studies.log", f"{d.rsplit('/', 1)[1]}-{study}"), "--units", units,
                           "--seeds", 10, "--first-seed", 1000, "--timesteps", 1000000, "--learning-rate", "3e-4", NOT_SAVED),
                compare(f"{label}, lr 1e-4={f}/test/summary.json", f"{label}, lr 3e-4={f}/ermrl-lr3e-4/summary.json",
                        "--compare", f"{label}, lr 3e-4", f"{label}, lr 1e-4",
                        "--title", "evolved Φ* at PPO lr 1e-4 and 3e-4, the same seeds",
                        "--figure", f"{f}/lr3e-4-vs-1e-4.png", tee=f"{f}/lr3e-4-vs-1e-4.md"))


def sizes() -> Step:
    d = "docs/data/reservoir-sizes-small"
    tables = []
    for env in ("cartpole", "pendulum"):
        labels = [f"{n} units={d}/{env}-{n}u/test/summary.json" for n in SIZES]
        against = [("--compare", f"{n} units", "100 units") for n in SIZES if n != 100]
        tables.append(compare(labels, against, "--figure", f"{d}/{env}.png", tee=f"{d}/{env}.md"))
    return step("sizes", "C14", "C14: CartPoleNoVel and PendulumNoVel at 25 to 1000 units, small evolutions, each "
                "tested 10 × 1M (the experiment's two Humanoid studies are left out)",
                experiment("reservoir-sizes", "small", "--only", [f"{env}-{n}u" for env in ("cartpole", "pendulum")
                                                                  for n in SIZES], TEST10),
                tables)


def sizes_medium() -> Step:
    d, s = "docs/data/reservoir-sizes-medium", "docs/data/reservoir-sizes-small"
    return step("sizes_medium", "C2 C14", "C14 and the Pendulum target: PendulumNoVel at 500 and 1000 units with the "
                "paper's per-trial budget (medium), tested 10 × 1M at lr 1e-4; then the default Φ at 500 units",
                experiment("reservoir-sizes", "medium", "--only", "pendulum-500u", "pendulum-1000u", TEST10),
                train_once(f"{d}/default-phi-500u", "--env", "PendulumNoVel-v1", "--units", 500, DEFAULT_PHI,
                           "--seeds", 10, "--first-seed", 1000, "--timesteps", 1000000, "--learning-rate", "1e-4", NOT_SAVED),
                compare(f"500 units={d}/pendulum-500u/test/summary.json",
                        f"1000 units={d}/pendulum-1000u/test/summary.json",
                        f"500 units small={s}/pendulum-500u/test/summary.json",
                        f"1000 units small={s}/pendulum-1000u/test/summary.json",
                        f"100 units small={s}/pendulum-100u/test/summary.json",
                        f"default Φ 500 units={d}/default-phi-500u/summary.json",
                        "default Φ 100 units=docs/data/fitness-1m/default-phi-pendulum/summary.json",
                        "--compare", "500 units", "500 units small", "--compare", "1000 units", "1000 units small",
                        "--compare", "500 units", "100 units small", "--compare", "500 units", "default Φ 500 units",
                        "--compare", "1000 units", "default Φ 500 units",
                        "--compare", "500 units", "default Φ 100 units",
                        "--compare", "default Φ 500 units", "default Φ 100 units",
                        "--title", "reservoir sizes, medium evolutions", "--figure", f"{d}/pendulum.png",
                        tee=f"{d}/pendulum.md"))


def sizes_medium_lr3e4() -> Step:
    return at_lr3e4("sizes_medium_lr3e4", "C6", "C6 / the Pendulum target: the 500-unit medium Φ* (evolved and "
                    "selected at lr 3e-4, tested at 1e-4) on the same test seeds at 3e-4, ER-MRL only, paired with "
                    "its 1e-4 test", "docs/data/reservoir-sizes-medium", "pendulum-500u", "PendulumNoVel-v1", 500,
                    "500 units")


def probe_sizes() -> Step:
    probes = []
    for env, units, scale, study in (("CartPoleNoVel-v1", 500, "small", "cartpole"),
                                     ("PendulumNoVel-v1", 500, "medium", "pendulum"),
                                     ("PendulumNoVel-v1", 1000, "medium", "pendulum")):
        d = f"docs/data/reservoir-sizes-{scale}"
        probes.append(ermrl("analyze", "probe", "--env", env, "--units", units, "--study",
                            f"reservoir-sizes-{scale}-{study}-{units}u", "--storage", f"{d}/studies.log", "--out",
                            f"{d}/probe/{study}-{units}u.png", skip_if=made(f"{d}/probe/{study}-{units}u.md")))
    return step("probe_sizes", "C4", "C4 at C14's sizes: velocity R² of the 500-unit CartPole Φ* (small) and the 500- "
                "and 1000-unit Pendulum Φ* (medium), against the default Φ and a memoryless reservoir", probes)


OTHER_HPS = (("default", ()), ("rc 0.02", ("--rc-connectivity", "0.02")), ("rc 1", ("--rc-connectivity", "1")),
             ("input 0.5", ("--input-connectivity", "0.5")), ("input 1", ("--input-connectivity", "1")),
             ("no bias", ("--bias", "none")), ("bias 0.1", ("--bias-scaling", "0.1")))
"""C17's variants: ReservoirPy's other hyperparameters one at a time around its defaults (connectivities 0.1, bias
±1 on 10% of the units)."""


def other_hps() -> Step:
    actions = []
    for env in ("CartPoleNoVel-v1", "PendulumNoVel-v1"):
        d, labels, against = f"docs/data/other-hps/{env}", [], []
        for name, flags in OTHER_HPS:
            folder = f"{d}/{name.replace(' ', '-')}"
            actions.append(train_once(folder, "--env", env, "--seeds", 10, "--first-seed", 1000, "--timesteps",
                                      300000, flags, NOT_SAVED))
            labels.append(f"{name}={folder}/summary.json")
            against += [] if name == "default" else ["--compare", name, "default"]
        actions.append(compare(labels, against, "--figure", f"{d}/curves.png", tee=f"{d}/summary.md"))
    # why input connectivity matters on Pendulum: how much of the reservoir saturates, and the velocity it keeps
    actions.append(python("paper/input_saturation.py", "--out", "docs/data/other-hps/saturation.md"))
    return step("other_hps", "C17", "C17: ReservoirPy's other hyperparameters one at a time, with the default Φ on "
                "CartPoleNoVel and PendulumNoVel, 10 seeds × 300k each; then the reservoir's input saturation",
                actions)
