"""paper/input_saturation.py (C17's likely reason): dense input saturates the reservoir on PendulumNoVel, whose
reward (−16..0) and torque (±2) enter unnormalized, and the saturated state loses the deleted velocity. Real
Pendulum episodes, real reservoirs."""

import re
from pathlib import Path

import numpy as np

from ermrl.analysis.probe import MEMORY, collect, reservoir_states
from ermrl.reservoir import ReservoirSpec

from cli_runs import script

SCRIPT = Path(__file__).resolve().parent.parent / "paper" / "input_saturation.py"


def _run(*args):
    return script(SCRIPT, *args)


def test_the_spec_reaches_the_probes_reservoir():
    """reservoir_states builds the reservoir from ``spec``: with every input weight drawn, no unit is left
    without input, so on Pendulum more units sit near ±1 than with ReservoirPy's 10%."""
    rollouts = collect("Pendulum-v1", 3, seed=0)
    sparse, dense = (np.abs(reservoir_states("PendulumNoVel-v1", rollouts, MEMORY, spec=ReservoirSpec(
        input_connectivity=c))) for c in (0.1, 1.0))
    assert sparse.shape == dense.shape == (len(rollouts.obs), 100)
    assert np.mean(dense > 0.95) > 3 * np.mean(sparse > 0.95)


def test_dense_input_saturates_pendulums_reservoir_and_loses_the_velocity(tmp_path):
    out = tmp_path / "saturation.md"
    done = _run("--env", "PendulumNoVel-v1", "--input-connectivity", 0.1, 1, "--draws", 1, "--episodes", 12,
                "--out", out)
    assert done.returncode == 0, done.stderr
    assert out.read_text() == done.stdout
    rows = {float(m[1]): tuple(map(float, m.groups()[1:])) for m in re.finditer(
        r"\| PendulumNoVel-v1 \| 2,412 \| ([\d.]+) \| ([\d.]+) ± 0\.000 \| ([\d.]+) ± 0\.000 \| (-?[\d.]+) ± 0\.000 \|",
        done.stdout)}
    assert sorted(rows) == [0.1, 1.0], done.stdout
    (sat_sparse, abs_sparse, r2_sparse), (sat_dense, abs_dense, r2_dense) = rows[0.1], rows[1.0]
    assert sat_sparse < 0.2 < 0.5 < sat_dense and abs_sparse < abs_dense
    assert r2_sparse > 0.8 and r2_dense < 0.5


def test_bad_input_is_one_line_before_any_rollout():
    done = _run("--env", "CartPole-v1")
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr.startswith("input_saturation.py: error: 'CartPole-v1' deletes no velocity, so there is "
                                  "nothing to probe; use one of CartPoleNoVel-v1, PendulumNoVel-v1")
    assert done.stderr.count("\n") == 1
    done = _run("--input-connectivity", 0)
    assert (done.returncode, done.stderr) == (2, "input_saturation.py: error: input_connectivity must be in (0, 1], "
                                                 "got 0.0; it is a fraction of the weights (ReservoirPy's default: "
                                                 "0.1)\n")
    done = _run("--draws", 0)
    assert (done.returncode, done.stderr) == (2, "input_saturation.py: error: --draws must be >= 1 and --episodes >= 2, "
                                                 "got 0 and 100\n")
    done = _run("--out", SCRIPT.parent)
    assert (done.returncode, done.stderr) == (2, f"input_saturation.py: error: --out {SCRIPT.parent} is a folder; give a "
                                                 f"file path such as {SCRIPT.parent / 'saturation.md'}\n")
