"""How much of the reservoir's tanh is saturated, for several input connectivities (C17's likely reason).

The C17 sweep (docs/data/other-hps/) found that input connectivity 0.5 or 1 drops PendulumNoVel to the level of a
random agent, while CartPoleNoVel does not care. The reservoir's input u_t = (masked o_t, a_{t−1}, r_{t−1}) is not
normalized. Pendulum feeds a reward in −16..0 and a torque in ±2. With dense input, every unit sums such terms, and
tanh sits at ±1, where the state carries little beyond the sign.

The script feeds random-policy episodes of the base env to reservoirs with the default Φ (sr 0.95, lr 0.5, iss 1),
as the agent feeds them (ermrl.analysis.probe.reservoir_states). For each input connectivity and each reservoir
draw it reports three numbers:
- the fraction of unit-steps with |x| > 0.95;
- the mean |x|;
- the velocity R² of the linear probe, that is, how much of the deleted velocities the state still holds.

Usage:
    .venv/bin/python paper/input_saturation.py [--env PendulumNoVel-v1 CartPoleNoVel-v1]
        [--input-connectivity 0.1 0.5 1] [--draws 3] [--episodes 100] [--out docs/data/other-hps/saturation.md]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

SATURATED = 0.95
"""|x| above which a tanh unit counts as saturated (its slope is below 1 − 0.95² ≈ 0.1)."""


def measure(env_id: str, connectivities: list[float], draws: int, episodes: int) -> list[dict]:
    """One row per input connectivity: saturation, mean |x| and velocity R², each as (mean, std) over ``draws``
    reservoir draws (seeds 0..draws−1) fed the same ``episodes`` random episodes of the base env."""
    from ermrl.analysis.probe import MEMORY, collect, probe, reservoir_states
    from ermrl.envs import masking
    from ermrl.reservoir import ReservoirSpec

    rollouts = collect(masking.parse(env_id)[0], episodes, seed=0)
    rows = []
    for connectivity in connectivities:
        spec = ReservoirSpec(input_connectivity=connectivity)
        saturated, magnitude, r2 = [], [], []
        for seed in range(draws):
            states = np.abs(reservoir_states(env_id, rollouts, MEMORY, seed=seed, spec=spec))
            saturated.append(float(np.mean(states > SATURATED)))
            magnitude.append(float(np.mean(states)))
            r2.append(probe(env_id, MEMORY, seed=seed, rollouts=rollouts, spec=spec).r2_velocity)
        rows.append({"env": env_id, "input_connectivity": connectivity, "steps": len(rollouts.obs),
                     **{name: (float(np.mean(v)), float(np.std(v)))
                        for name, v in (("saturated", saturated), ("mean_abs", magnitude), ("velocity_r2", r2))}})
    return rows


def table(rows: list[dict], draws: int) -> str:
    """The rows as a markdown table (mean ± std over the reservoir draws)."""
    lines = [f"| env | steps | input connectivity | unit-steps with \\|x\\| > {SATURATED} | mean \\|x\\| | velocity R² |",
             "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        cells = [f"{r[k][0]:.3f} ± {r[k][1]:.3f}" for k in ("saturated", "mean_abs", "velocity_r2")]
        lines.append(f"| {r['env']} | {r['steps']:,} | {r['input_connectivity']:g} | " + " | ".join(cells) + " |")
    lines.append(f"\nDefault Φ (sr 0.95, lr 0.5, iss 1), 100 units; mean ± std over {draws} reservoir draws, all fed "
                 "the same random-policy episodes (steps: their total).")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", nargs="+", default=["PendulumNoVel-v1", "CartPoleNoVel-v1"], help="NoVel env ids")
    p.add_argument("--input-connectivity", nargs="+", type=float, default=[0.1, 0.5, 1.0],
                   help="fractions of non-zero input weights (default: 0.1 0.5 1)")
    p.add_argument("--draws", type=int, default=3, help="reservoir draws (seeds 0..N−1) per setting (default: 3)")
    p.add_argument("--episodes", type=int, default=100, help="random-policy episodes per env (default: 100)")
    p.add_argument("--out", type=Path, help="also write the table here (markdown)")
    a = p.parse_args(argv)
    from ermrl import storage
    from ermrl.envs import masking
    from ermrl.errors import ConfigError
    from ermrl.reservoir import ReservoirSpec

    try:  # every input checked before any rollout
        if a.draws < 1 or a.episodes < 2:
            raise ConfigError(f"--draws must be >= 1 and --episodes >= 2, got {a.draws} and {a.episodes}")
        for env in a.env:
            if not masking.parse(env)[1]:
                known = ", ".join(map(masking.novel_id, masking.VELOCITY_DIMS))
                raise ConfigError(f"{env!r} deletes no velocity, so there is nothing to probe; use one of {known}")
        for c in a.input_connectivity:
            ReservoirSpec(input_connectivity=c)
        if a.out:
            storage.check_file(a.out, "--out", example="saturation.md")
        rows = [r for env in a.env for r in measure(env, a.input_connectivity, a.draws, a.episodes)]
    except ConfigError as error:
        print(f"input_saturation.py: error: {error}", file=sys.stderr)
        return 2
    text = table(rows, a.draws)
    print(text, end="")
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        storage.write_text(a.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
