"""The names a reader sees for a test phase's ER-MRL models and a study's parameters, and the reading of the
names older versions wrote.

An ER-MRL model is labelled with its learning rate and its Φ, each spelled out, e.g. "ER-MRL (learning rate
0.0003; sr 0.95, leak rate 0.236, iss 1)": in RL, "lr" reads as a learning rate, where Φ's lr is the reservoir's
leak rate. Numbers are rounded for reading (4 significant digits). Versions before this wording labelled the same
model "ER-MRL lr 0.0003 (sr 0.95, lr 0.236, iss 1)" (with several learning rates) or "ER-MRL (sr 0.95, lr 0.236,
iss 1)" (with one); :func:`current` reads those labels in today's wording, so that the curves and summaries they
wrote show as new ones do, and :func:`older_ermrl_labels` gives them back, so that an unfinished test phase of
theirs keeps its finished models. It imports nothing of ermrl, so that the readers of stored files can use it.
"""

from __future__ import annotations

import re

PHI_NAMES = {"sr": "spectral radius", "lr": "leak rate", "iss": "input scaling"}
"""Φ's fields as a reader reads them; in RL, "lr" is a learning rate."""


def param_name(key: str) -> str:
    """A study's parameter as a reader reads it: ``lr`` and ``lr_2`` (the leak rates) spelled out, since in RL
    "lr" reads as a learning rate; ``sr_1``, ``iss`` as they are."""
    return key.replace("lr", "leak rate", 1) if key.startswith("lr") else key


def number(value: float) -> str:
    """``value`` for reading: 4 significant digits, a short exponent (3e-4 -> "0.0003", 5e-5 -> "5e-5")."""
    return re.sub(r"e([+-])0*(\d)", r"e\1\2", f"{float(value):.4g}").replace("e+", "e")


def phi_text(phi, k: int, trial: int) -> str:
    """Φ of one reservoir as "sr 0.95, leak rate 0.236, iss 1"; with K != 1 reservoirs, "trial N" (the trial
    whose Φ it is). ``phi``: (sr, lr, iss), each holding the reservoirs' values."""
    if k != 1:
        return f"trial {trial}"
    return ", ".join(f"{name} {number(values[0])}" for name, values in zip(("sr", "leak rate", "iss"), phi))


def ermrl_label(learning_rate: float, phi: str) -> str:
    """The label of the ER-MRL model that trains at ``learning_rate`` with Φ as :func:`phi_text` writes it."""
    return f"ER-MRL (learning rate {number(learning_rate)}; {phi})"


def ermrl_folder(learning_rate: float) -> str:
    """The agents' folder of the ER-MRL model at ``learning_rate`` in a test phase of several learning rates."""
    return f"ermrl-learning-rate-{number(learning_rate)}"


def older_ermrl_labels(phi, k: int, trial: int, learning_rates) -> list[str]:
    """The labels that versions before this wording gave the ER-MRL models of a test phase, one per learning
    rate: what an unfinished test phase of theirs keeps its finished models under."""
    shown = f"trial {trial}" if k != 1 else ", ".join(f"{n} {float(v[0]):.3g}"
                                                       for n, v in zip(("sr", "lr", "iss"), phi))
    if len(learning_rates) == 1:
        return [f"ER-MRL ({shown})"]
    return [f"ER-MRL lr {rate:g} ({shown})" for rate in learning_rates]


_OLD_RATE = re.compile(r"ER-MRL lr (\d+(?:\.\d*)?(?:e[+-]?\d+)?)(?: \((.*)\))?")
_OLD_PHI = re.compile(r"ER-MRL \((.*\blr\b.*)\)")


def current(label: str) -> str:
    """``label`` in today's wording: an ER-MRL label written by an older version (``ER-MRL lr 0.0003 (sr 0.508,
    lr 0.0568, iss 1)``) as "ER-MRL (learning rate 0.0003; sr 0.508, leak rate 0.0568, iss 1)"; any other label
    as it is."""
    if m := _OLD_RATE.fullmatch(label):
        rate, phi = m.groups()
        return f"ER-MRL (learning rate {number(float(rate))}" + (f"; {_leak_rate(phi)})" if phi else ")")
    if m := _OLD_PHI.fullmatch(label):
        return f"ER-MRL ({_leak_rate(m.group(1))})"
    return label


def _leak_rate(phi: str) -> str:
    """An older Φ text ("sr 0.508, lr 0.0568, iss 1") with the leak rate spelled out."""
    return re.sub(r"\blr\b", "leak rate", phi)
