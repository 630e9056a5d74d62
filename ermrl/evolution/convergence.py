"""When a CMA-ES study is done: the search distribution's spread per generation, and the stopping rule.

Optuna's ``CmaEsSampler`` keeps its ``cmaes.CMA`` optimizer, pickled, in the system attributes
(``cma:optimizer:0``, ``:1``, ...) of the first trial sampled in each CMA generation: while sampling that trial it
tells the optimizer the previous generation's fitness, then stores it. The optimizer's search distribution,
N(m, σ²C), lives in Optuna's transformed space, where each log-uniform parameter is mapped linearly from
[log lo, log hi] to [0, 1], parameters in name order. The **spread** of a searched parameter is that
distribution's standard deviation along it, in decades of the parameter:

    spread_i = σ · sqrt(C_ii) · log10(hi_i / lo_i)

ermrl's generation g > 0 was sampled from CMA generation g − 1's distribution; generation 0 is the sampler's
random startup, which has none (see :mod:`ermrl.evolution.generations`). CMA generation 0's distribution is never
stored (nothing was told yet), so the spreads start at generation 2.

**The rule** (:class:`Convergence`): a study has converged at generation g when g and the G − 1 generations before
it were each sampled with a spread below W decades in every searched parameter, and generation g has all its
trials complete. The defaults, W = 0.01 decades (each Φ within about ±2.3 % of the mean at one standard deviation)
and G = 3, stop the paper's 900-trial CartPoleNoVel study at generation 32, 198 trials in
(``ermrl convergence``; docs/results.md).
"""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import optuna
from optuna.trial import FrozenTrial, TrialState

from ermrl.errors import ConfigError
from ermrl.evolution.generations import ATTR as GENERATION
from ermrl.evolution.generations import CMA_GENERATION
from ermrl.evolution.search_space import SearchSpace

OPTIMIZER_KEY = "cma:optimizer:"
"""The prefix of the system attributes in which Optuna's CmaEsSampler stores its pickled optimizer."""
RECORD = "converged"
"""The study user attribute written when a study stops by the rule: see :func:`record`."""
MAX_WIDTH = 10.0
MAX_GENERATIONS = 1000


@dataclasses.dataclass(frozen=True)
class Convergence:
    """Stop a CMA-ES study once ``generations`` generations in a row were sampled with a spread below ``width``
    decades in every searched parameter."""

    width: float = 0.01
    """The widest spread, in decades of each searched parameter (a standard deviation in log10 units), that counts
    as converged."""
    generations: int = 3
    """How many generations in a row must each be sampled with every spread below the width."""

    def __post_init__(self):
        if not (math.isfinite(self.width) and 0 < self.width <= MAX_WIDTH):
            raise ConfigError(f"`width` must be in (0, {MAX_WIDTH:g}] decades, got {self.width}", owner=type(self))
        if not 1 <= self.generations <= MAX_GENERATIONS:
            raise ConfigError(f"`generations` must be in 1..{MAX_GENERATIONS}, got {self.generations}",
                              owner=type(self))

    def describe(self) -> str:
        return f"spread below {self.width:g} decades in every parameter for {self.generations} generations"


def _optimizer(trial: FrozenTrial):
    """The CMA-ES optimizer Optuna stored on ``trial`` (in chunks), or None where it stored none or a process
    killed while it wrote them left only some (the trial then failed; its generation's other trials hold the same
    optimizer). Optuna's own sampler reads only completed trials' copies."""
    parts = {k: v for k, v in trial.system_attrs.items() if k.startswith(OPTIMIZER_KEY)}
    if not parts:
        return None
    try:
        return pickle.loads(bytes.fromhex("".join(parts[f"{OPTIMIZER_KEY}{i}"] for i in range(len(parts)))))
    except (KeyError, ValueError, EOFError, pickle.UnpicklingError):
        return None  # a chunk missing, or the last ones never written


def centers_and_spreads(trials: list[FrozenTrial], space: SearchSpace) -> dict[int, dict[str, tuple[float, float]]]:
    """{generation: {parameter: (the distribution's mean as a Φ value, its spread in decades)}} for every
    generation whose sampling distribution the study holds (from generation 2 on), read from the optimizers
    Optuna stored."""
    widths = {name: (math.log10(d.low), math.log10(d.high / d.low))
              for name, d in sorted(space.distributions().items())}
    out: dict[int, dict[str, tuple[float, float]]] = {}
    for t in sorted(trials, key=lambda t: t.number):
        tag = t.system_attrs.get(CMA_GENERATION)
        if tag is not None and int(tag) + 1 in out:
            continue  # this generation's distribution is read already (Optuna stores one on many trials)
        opt = _optimizer(t)
        if opt is None or opt.generation + 1 in out:
            continue
        sd = opt._sigma * np.sqrt(np.diag(opt._C))  # cmaes.CMA keeps σ and C private; no public accessor
        if len(sd) != len(widths):
            continue  # another search space (Optuna's independent sampler took over): no spread to read
        out[opt.generation + 1] = {name: (float(10 ** (low + m * w)), float(s * w))
                                   for (name, (low, w)), s, m in zip(widths.items(), sd, opt.mean)}
    return out


def spreads(trials: list[FrozenTrial], space: SearchSpace) -> dict[int, dict[str, float]]:
    """{generation: {parameter: spread in decades}}: :func:`centers_and_spreads` without the centers."""
    return {g: {name: s for name, (_, s) in d.items()} for g, d in centers_and_spreads(trials, space).items()}


def complete_generations(trials: list[FrozenTrial], popsize: int) -> set[int]:
    """The generations with at least ``popsize`` COMPLETE trials (ermrl's generation user attribute)."""
    counts: dict[int, int] = {}
    for t in trials:
        if t.state == TrialState.COMPLETE and GENERATION in t.user_attrs:
            counts[int(t.user_attrs[GENERATION])] = counts.get(int(t.user_attrs[GENERATION]), 0) + 1
    return {g for g, n in counts.items() if n >= popsize}


def stop_generation(spread: dict[int, dict[str, float]], rule: Convergence, complete: set[int] | None = None) -> int | None:
    """The first generation at which ``rule`` holds on ``spread`` (and which is in ``complete``, when given), or
    None."""
    streak, previous = 0, None
    for g in sorted(spread):
        narrow = all(v < rule.width for v in spread[g].values())
        streak = (streak + 1 if previous == g - 1 else 1) if narrow else 0
        previous = g
        if streak >= rule.generations and (complete is None or g in complete):
            return g
    return None


@dataclasses.dataclass(frozen=True)
class Projection:
    """Where the rule would hold if each parameter's spread kept shrinking as it did over ``window`` (the
    generations of a log-linear least-squares fit of log10 spread against generation, one per parameter).
    An extrapolation of a noisy trend, to size a run, not a prediction."""

    window: tuple[int, int]
    """The first and last generation of the fit."""
    factors: dict[str, float]
    """{parameter: the fitted factor its spread is multiplied by each generation} (< 1: shrinking)."""
    generation: float | None
    """The generation at which the rule would hold (the slowest parameter reaching the width, plus the rule's
    generations in a row), or None when a parameter's spread above the width is not shrinking."""

    def slowest(self) -> str:
        """The parameter whose spread shrinks slowest."""
        return max(self.factors, key=self.factors.get)

    def describe(self) -> str:
        """"at the rates of generations 11–19 (sr_1's spread shrinks slowest, × 0.997 a generation), the rule would
        hold at about generation 1,467", or, when a spread is not shrinking, "over generations 11–20, iss_1's
        spread did not shrink (× 1.003 a generation)"."""
        (first, last), name = self.window, self.slowest()
        if self.generation is None:
            return (f"over generations {first}–{last}, {name}'s spread did not shrink (× {self.factors[name]:.3f} a "
                    "generation)")
        return (f"at the rates of generations {first}–{last} ({name}'s spread shrinks slowest, × "
                f"{self.factors[name]:.3f} a generation), the rule would hold at about generation "
                f"{math.ceil(self.generation):,}")


MIN_WINDOW = 5
"""The fewest generations a projection is fitted on."""

RECENT_WINDOW = 8
"""The generations of the recent projection that ``ermrl convergence`` gives beside the default one once the later
half is longer: the later half can average a spread that narrows again over a stretch where it widened."""


def _later_half(generations: int) -> int:
    """The default projection's window for a spread of ``generations`` generations: the later half, at least
    :data:`MIN_WINDOW`."""
    return max(MIN_WINDOW, (generations + 1) // 2)


def project(spread: dict[int, dict[str, float]], rule: Convergence, window: int | None = None) -> Projection | None:
    """Fits each parameter's log10 spread against the generation over the last ``window`` generations of
    ``spread`` (default: the later half, at least :data:`MIN_WINDOW`) and returns where ``rule`` would hold at
    those rates; None when ``spread`` has fewer than :data:`MIN_WINDOW` generations. On the paper's 900-trial
    CartPoleNoVel study, fitted at any generation from 10 to 32 it says 25–34; the rule holds at 32."""
    generations = sorted(spread)
    size = _later_half(len(generations)) if window is None else window
    if size < 2:
        raise ConfigError(f"`window` must be >= 2 generations, got {window}", owner=project)
    if len(generations) < max(size, MIN_WINDOW):
        return None
    fitted = generations[-size:]
    last, factors, reach = fitted[-1], {}, []
    for name in sorted(spread[last]):
        slope, at_zero = np.polyfit(fitted, np.log10([max(spread[g][name], 1e-300) for g in fitted]), 1)
        factors[name] = float(10 ** slope)
        now = at_zero + slope * last
        if now < math.log10(rule.width):
            reach.append(float(last))
        elif slope < 0:
            reach.append(last + (math.log10(rule.width) - now) / slope)
        else:
            reach.append(math.inf)
    stop = max(reach) + rule.generations - 1
    return Projection((fitted[0], last), factors, None if math.isinf(stop) else stop)


def recent_projection(spread: dict[int, dict[str, float]], rule: Convergence) -> Projection | None:
    """:func:`project` on the last :data:`RECENT_WINDOW` generations of ``spread``, or None while the later half
    (the default projection's window) is no longer than that."""
    if _later_half(len(spread)) <= RECENT_WINDOW:
        return None
    return project(spread, rule, window=RECENT_WINDOW)


def projection_history(spread: dict[int, dict[str, float]], rule: Convergence, last: int = 10
                       ) -> dict[int, float | None]:
    """{generation g: the generation :func:`project` gave (None: a spread not shrinking) on the spreads up to g},
    for each of the last ``last`` generations of ``spread`` with enough generations for a projection: how much the
    projection moves from one generation to the next (on a study whose mean is still moving, a lot)."""
    generations = sorted(spread)
    out: dict[int, float | None] = {}
    for g in generations[-last:]:
        projection = project({k: spread[k] for k in generations if k <= g}, rule)
        if projection is not None:
            out[g] = projection.generation
    return out


def fitness_correlations(trials: list[FrozenTrial], space: SearchSpace, generations: tuple[int, int]
                         ) -> dict[str, tuple[float, float]]:
    """{parameter: (Spearman's ρ, its two-sided p-value)} of fitness against each searched parameter over the
    COMPLETE trials of ``generations`` (first, last; inclusive): whether Φ still orders the fitness there. A
    parameter along which the fitness is flat at this seed noise gives CMA-ES no reason to narrow it. Empty with
    fewer than 3 trials."""
    from scipy.stats import spearmanr

    first, last = generations
    done = [t for t in trials if t.state == TrialState.COMPLETE and first <= int(t.user_attrs.get(GENERATION, -1)) <= last]
    if len(done) < 3:
        return {}
    values = [t.value for t in done]
    out = {}
    for name in sorted(space.distributions()):
        result = spearmanr([t.params[name] for t in done], values)
        out[name] = (float(result.statistic), float(result.pvalue))
    return out


@dataclasses.dataclass(frozen=True)
class Verdict:
    """Where a study stands under a rule."""

    generation: int | None
    """The generation at which the rule holds, or None."""
    trials: int
    """COMPLETE trials of generations up to ``generation`` (all COMPLETE trials when it is None)."""
    spread: dict[int, dict[str, float]]


def judge(study: optuna.Study, space: SearchSpace, popsize: int, rule: Convergence,
          trials: list[FrozenTrial] | None = None) -> Verdict:
    """Applies ``rule`` to ``study`` (its trials, or ``trials``)."""
    trials = study.get_trials(deepcopy=False) if trials is None else trials
    spread = spreads(trials, space)
    g = stop_generation(spread, rule, complete_generations(trials, popsize))
    done = [t for t in trials if t.state == TrialState.COMPLETE
            and (g is None or int(t.user_attrs.get(GENERATION, 0)) <= g)]
    return Verdict(g, len(done), spread)


def record(study: optuna.Study, rule: Convergence, verdict: Verdict) -> dict:
    """Writes and returns the study's ``converged`` user attribute: the generation, the trials completed up to
    it, the rule, and the spreads of its last generation."""
    value = {"generation": verdict.generation, "trials": verdict.trials, "width": rule.width,
             "generations": rule.generations, "spread": verdict.spread[verdict.generation]}
    study.set_user_attr(RECORD, value)
    return value


def recorded(study: optuna.Study, rule: Convergence | None = None) -> dict | None:
    """The study's ``converged`` record, if any (and, with ``rule``, only if written under that rule)."""
    value = study.user_attrs.get(RECORD)
    if not isinstance(value, dict) or value.get("generation") is None:
        return None
    if rule is not None and (value.get("width"), value.get("generations")) != (rule.width, rule.generations):
        return None
    return value
