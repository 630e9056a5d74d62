"""The names readers see for the test phase's ER-MRL models: the learning rate and the leak rate spelled out, and
the labels older versions wrote (``ER-MRL lr 0.0003 (sr 0.508, lr 0.0568, iss 1)``) read in today's wording."""

from pathlib import Path

import numpy as np
import pytest

from ermrl import model_labels, storage
from ermrl.analysis.experiment_report import aggregate_name

PAPER_TEST = Path(__file__).resolve().parents[1] / "docs/data/partial-observability-paper/cartpole-1res/test"
"""A committed test phase of three learning rates, written before today's wording."""
SIZES_TEST = Path(__file__).resolve().parents[1] / "docs/data/reservoir-sizes-small/cartpole-100u/test"
"""A committed test phase of one learning rate, written before today's wording."""


@pytest.mark.parametrize("value, text", [(3e-4, "0.0003"), (0.0003000000142492354, "0.0003"), (5e-5, "5e-5"),
                                         (0.2361234, "0.2361"), (1.0, "1"), (1e6, "1e6"), (0.95, "0.95")])
def test_numbers_read_with_four_significant_digits(value, text):
    assert model_labels.number(value) == text


def test_an_ermrl_label_spells_out_the_learning_rate_and_the_leak_rate():
    phi = (np.array([0.95], np.float32), np.array([0.2361234]), np.array([1.0]))
    assert model_labels.ermrl_label(3e-4, model_labels.phi_text(phi, 1, 4)) == \
        "ER-MRL (learning rate 0.0003; sr 0.95, leak rate 0.2361, iss 1)"
    assert model_labels.ermrl_label(1e-4, model_labels.phi_text(phi, 2, 4)) == "ER-MRL (learning rate 0.0001; trial 4)"
    assert model_labels.ermrl_folder(5e-5) == "ermrl-learning-rate-5e-5"
    assert model_labels.older_ermrl_labels(phi, 1, 4, (3e-4, 5e-5)) == [
        "ER-MRL lr 0.0003 (sr 0.95, lr 0.236, iss 1)", "ER-MRL lr 5e-05 (sr 0.95, lr 0.236, iss 1)"]
    assert model_labels.older_ermrl_labels(phi, 2, 4, (3e-4,)) == ["ER-MRL (trial 4)"]


@pytest.mark.parametrize("old, now", [
    ("ER-MRL lr 0.0003 (sr 0.508, lr 0.0568, iss 1)", "ER-MRL (learning rate 0.0003; sr 0.508, leak rate 0.0568, iss 1)"),
    ("ER-MRL lr 5e-05 (trial 6)", "ER-MRL (learning rate 5e-5; trial 6)"),
    ("ER-MRL lr 0.0001", "ER-MRL (learning rate 0.0001)"),
    ("ER-MRL (sr 0.414, lr 0.123, iss 1)", "ER-MRL (sr 0.414, leak rate 0.123, iss 1)"),
    # today's labels and the others stay as they are
    ("ER-MRL (learning rate 0.0003; sr 0.95, leak rate 0.5, iss 1)",
     "ER-MRL (learning rate 0.0003; sr 0.95, leak rate 0.5, iss 1)"),
    ("ER-MRL (trial 6)", "ER-MRL (trial 6)"),
    ("ER-MRL (1 reservoir)", "ER-MRL (1 reservoir)"),
    ("PPO (same observation)", "PPO (same observation)"),
    ("PPO-LSTM (same observation)", "PPO-LSTM (same observation)"),
])
def test_a_label_of_an_older_version_reads_in_todays_wording(old, now):
    assert model_labels.current(old) == now


def test_a_committed_test_phase_of_an_older_version_reads_in_todays_wording():
    """docs/data's summaries and curves, written with "ER-MRL lr 0.0003 (sr 0.508, lr 0.0568, iss 1)", read with
    today's labels, the same in both files, and nothing a reader sees says "lr"."""
    rows = storage.read_test_summary(PAPER_TEST)
    models = [r["model"] for r in rows]
    assert models == [f"ER-MRL (learning rate {rate}; sr 0.508, leak rate 0.0568, iss 1)"
                      for rate in ("0.0003", "0.0001", "5e-5")] + ["PPO (same observation)", "PPO (full observation)"]
    assert list(rows[0]["improvement"]) == ["PPO (same observation)", "PPO (full observation)"]
    curves = storage.read_curves_csv(PAPER_TEST / "curves.csv")
    assert list(curves) == models
    single = storage.read_test_summary(SIZES_TEST)
    assert single[0]["model"] == "ER-MRL (sr 0.414, leak rate 0.123, iss 1)"
    assert list(storage.read_curves_csv(SIZES_TEST / "curves.csv"))[0] == single[0]["model"]
    assert not any(" lr " in m for m in models + [single[0]["model"]])


def test_the_aggregate_over_envs_keeps_each_learning_rate_apart_for_old_and_new_labels():
    """With several learning rates in a test phase, each ER-MRL model counts apart in the aggregate, named by its
    learning rate, whether its label is today's or an older version's; with one, it is "ER-MRL"."""
    rows = storage.read_test_summary(PAPER_TEST)
    assert [aggregate_name(r, rows) for r in rows] == [
        "ER-MRL (learning rate 0.0003)", "ER-MRL (learning rate 0.0001)", "ER-MRL (learning rate 5e-5)", "PPO", "PPO"]
    old = [{"model": "ER-MRL lr 0.0003 (sr 1, lr 0.5, iss 1)", "learning_rate": 3e-4},
           {"model": "ER-MRL lr 0.0001 (sr 1, lr 0.5, iss 1)", "learning_rate": 1e-4},
           {"model": "PPO-LSTM (same observation)", "learning_rate": 3e-4}]  # no kind: read from the label
    assert [aggregate_name(r, old) for r in old] == ["ER-MRL (learning rate 0.0003)", "ER-MRL (learning rate 0.0001)",
                                                    "PPO-LSTM"]
    single = storage.read_test_summary(SIZES_TEST)
    assert [aggregate_name(r, single) for r in single] == ["ER-MRL", "PPO", "PPO"]


@pytest.mark.parametrize("key, shown", [("lr", "leak rate"), ("lr_2", "leak rate_2"), ("sr", "sr"), ("sr_1", "sr_1"),
                                        ("iss", "iss")])
def test_a_studys_parameters_read_with_the_leak_rate_spelled_out(key, shown):
    assert model_labels.param_name(key) == shown
