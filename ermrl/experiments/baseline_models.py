"""Trained PPO baselines shared between test phases (``--baseline-store DIR``).

A test phase's PPO baselines (vanilla PPO on the same and on the full observation, PPO-LSTM) do not depend on
Φ*: two test phases on one env with the same seeds, budget, learning rate and PPO settings train the same
models, to the last bit, under the same versions of JAX, MuJoCo and the rest (:mod:`ermrl.provenance`; each file
records them, and a reuse under other versions says so). The paper's experiments hold such pairs: the H2 test on Ant and the H3 test of the study
evolved on HalfCheetah and Swimmer train the same PPO on Ant (10 seeds × 1M steps, ≈ 1.5 h of host steps here),
as do the test phases of one env at several reservoir counts or sizes. A store keeps each trained baseline once,
as ``STORE/ENV/JOB-DIGEST.npz`` in the format of :mod:`ermrl.experiments.checkpoints`, where DIGEST hashes the
job's identity (its name and labels, its TrainConfig less the env workers, its seeds, learning rates and group
size); a later test phase with the same identity loads it instead of training it. The identity is checked in full on loading, and a
damaged file is ignored (the model is trained again and the file replaced).

ER-MRL models never go into the store: they depend on Φ*, and reusing them would hide a changed selection.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ermrl.experiments import checkpoints
from ermrl.training.results import Results


def path_for(store: Path, identity: dict) -> Path:
    """Where the baseline with this job ``identity`` (JSON-ready, with ``train.env_id``) is kept in ``store``."""
    text = json.dumps(checkpoints.plain(identity), sort_keys=True)
    digest = hashlib.sha256(text.encode()).hexdigest()[:20]
    env_id = str(identity.get("train", {}).get("env_id", "env"))
    return Path(store) / env_id / f"{identity.get('job', 'job')}-{digest}.npz"


def load(store: Path, identity: dict) -> tuple[Results | None, Path]:
    """(the kept results for ``identity`` or None, the file they were looked up in)."""
    path = path_for(store, identity)
    return checkpoints.load_job(path.parent, path.stem, identity), path


def save(store: Path, identity: dict, results: Results) -> Path:
    """Keeps ``results`` for ``identity`` (atomically; an existing file for it is replaced)."""
    path = path_for(store, identity)
    path.parent.mkdir(parents=True, exist_ok=True)
    return checkpoints.save_job(path.parent, path.stem, identity, results)
