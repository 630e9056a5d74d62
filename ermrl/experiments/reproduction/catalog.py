"""Every step of the paper's reproduction, in the order ``ermrl reproduce`` runs them, and how names pick steps: a
step's name (``h2_converged``) or a claim (``C7``: every step that serves it, in that order)."""

from __future__ import annotations

from functools import cache

from ermrl.errors import ConfigError
from ermrl.experiments.reproduction.actions import Step

ORDER = ("cartpole", "pendulum", "pendulum_medium", "pendulum_paper", "pendulum_lr1e4", "lunarlander",
         "lunarlander_1res", "lunarlander_medium", "lunarlander_lr3e4", "probe", "h2", "c8", "fft", "fft_early", "h3",
         "humanoid", "c13", "c16", "hpmap", "c11", "c11_2res", "peer", "seed_schedule", "seed_schedule_paper",
         "observed_units", "observed_units_lr3e4", "fitness_1m", "sizes", "sizes_medium", "sizes_medium_lr3e4",
         "probe_sizes", "pendulum_paper_500u", "pendulum_paper_500u_interim", "pendulum_500u_lr1e4",
         "pendulum_500u_near_default", "pendulum_500u_near_default_wide", "pendulum_500u_near_default_wide_50",
         "pendulum_500u_more_seeds", "pendulum_100u_near_default_wide", "deterministic_eval", "pendulum_rlzoo_ppo",
         "pendulum_normalize", "pendulum_rlzoo_sde", "pendulum_rlzoo_policy", "pendulum_rlzoo_evolve",
         "pendulum_rlzoo_lstm", "recurrent_vs_ermrl", "other_hps", "h2_converged", "h2_converged_interim",
         "h3_converged", "h3_converged_interim", "c8_converged", "c3_converged")
"""The steps' names in the order they run when none is named: a step reads what the steps before it wrote."""
CLAIMS = tuple(f"C{i}" for i in range(1, 18))


@cache
def steps() -> dict[str, Step]:
    """{name: step}, in :data:`ORDER`."""
    from ermrl.experiments.reproduction import appendix, locomotion, partial_observability, pendulum, rlzoo

    found = {s.name: s for m in (partial_observability, locomotion, appendix, pendulum, rlzoo) for s in m.steps()}
    assert set(found) == set(ORDER), set(found) ^ set(ORDER)
    return {name: found[name] for name in ORDER}


def select(words: list[str] | tuple[str, ...]) -> list[Step]:
    """The steps named by ``words`` (step names or claims, ``C1`` .. ``C17``), in the order given, each once; every
    step in :data:`ORDER` when ``words`` is empty. ConfigError (one line listing the valid ones) for any other word."""
    table = steps()
    unknown = [w for w in words if w not in table and w not in CLAIMS]
    if unknown:
        raise ConfigError(f"unknown step or claim {unknown[0]!r}; steps: {' '.join(ORDER)}; claims: "
                          f"{' '.join(CLAIMS)}")
    if not words:
        return list(table.values())
    chosen: dict[str, Step] = {}
    for w in words:
        for s in [table[w]] if w in table else [s for s in table.values() if w in s.claims]:
            chosen.setdefault(s.name, s)
    return list(chosen.values())
