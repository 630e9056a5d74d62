"""Env-steps per second of Gymnasium's MuJoCo envs (EnvGroup) against the batched MujocoGroup.

    .venv/bin/python benchmarks/mujoco_backend.py [--slots 64] [--steps 100] [--repeats 3]

For each task, every backend steps ``slots`` envs ``steps`` times with the same seeded random actions from the
same reset seeds (so the workload, falls and auto-resets included, is the same); the time of the steps (not of
the reset) is the median over ``repeats``. Printed as a Markdown table:

* ``EnvGroup``: Gymnasium's envs one after the other (``gymnasium.make``, passive checker off).
* ``MujocoGroup t=1 / t=2``: the batched group, physics on 1 or 2 threads; bit-exact to EnvGroup (checked here
  on the packed arrays).
* ``rollout t=1 / t=2``: ``mujoco.rollout`` over all slots per env step (``nstep=frame_skip``), physics only (no
  observation, reward or reset), with a zero warm start at every env step since rollout does not return the
  warm start it ends with. Not exact: the second table gives its drift from the exact physics.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

TASKS = ("HalfCheetah-v5", "Ant-v5", "Humanoid-v5")


def action_sequence(base_id: str, slots: int, steps: int) -> np.ndarray:
    from ermrl.envs.mujoco_group import MujocoGroup

    space = MujocoGroup(base_id, (0,), False, 0, 0).action_space
    rng = np.random.default_rng(0)
    return rng.uniform(space.low, space.high, size=(steps, slots, space.shape[0])).astype(np.float32)


def time_group(make, actions: np.ndarray, repeats: int) -> tuple[float, np.ndarray]:
    """Median seconds of ``len(actions)`` steps, and the packed output of the last step (for the check)."""
    group = make()
    seeds = np.arange(actions.shape[1])
    times = []
    for _ in range(repeats):
        group.reset(seeds)
        t = time.perf_counter()
        for a in actions:
            packed = group.step(a)
        times.append(time.perf_counter() - t)
    group.close()
    return statistics.median(times), packed


class RolloutStepper:
    """All slots' physics, one ``mujoco.rollout`` call per env step (nstep = frame_skip, the action held)."""

    def __init__(self, base_id: str, slots: int, threads: int):
        import mujoco
        from mujoco import rollout

        from ermrl.envs import mujoco_tasks
        from ermrl.envs.mujoco_group import MujocoGroup

        self.mujoco = mujoco
        self.spec = mujoco_tasks.task_spec(base_id)
        self.group = MujocoGroup(base_id, (0,), False, 0, slots)  # for the model and the exact reset states
        self.model = self.group.model
        self.scratch = [mujoco.MjData(self.model) for _ in range(threads)]
        self.roller = rollout.Rollout(nthread=threads if threads > 1 else 0)
        self.full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.nstate = mujoco.mj_stateSize(self.model, self.full)
        self.warmstart = np.zeros((slots, self.model.nv))
        self.out = np.empty((slots, self.spec.frame_skip, self.nstate))

    def reset(self, seeds: np.ndarray) -> None:
        self.group.reset(seeds)
        self.state = np.empty((len(seeds), self.nstate))
        for i, data in enumerate(self.group.datas):
            self.mujoco.mj_getState(self.model, data, self.state[i], self.full)

    def step(self, actions: np.ndarray) -> None:
        control = np.repeat(np.asarray(actions, np.float64)[:, None, :], self.spec.frame_skip, axis=1)
        self.roller.rollout([self.model], self.scratch, self.state, control, nstep=self.spec.frame_skip,
                            initial_warmstart=self.warmstart, state=self.out)
        self.state = self.out[:, -1].copy()

    def close(self):
        self.roller.close()
        self.group.close()


def rollout_drift(base_id: str, actions: np.ndarray, at=(1, 10, 100)) -> list[float]:
    """Max |difference| of qpos between the rollout stepping and the exact MujocoGroup after each count of steps."""
    from ermrl.envs.mujoco_group import MujocoGroup

    seeds = np.arange(actions.shape[1])
    exact, roller = MujocoGroup(base_id, (0,), False, 0, len(seeds)), RolloutStepper(base_id, len(seeds), 1)
    exact.reset(seeds)
    roller.reset(seeds)
    nq = exact.model.nq
    drift = []
    for t, a in enumerate(actions[:max(at)], start=1):
        exact._physics(np.arange(len(seeds)), a)  # physics only, no auto-reset: the same trajectories
        roller.step(a)
        if t in at:
            qpos = np.stack([d.qpos for d in exact.datas])
            drift.append(float(np.max(np.abs(roller.state[:, 1:1 + nq] - qpos))))  # state: time, qpos, ...
    exact.close()
    roller.close()
    return drift


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--slots", type=int, default=64)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--tasks", nargs="+", default=list(TASKS))
    p.add_argument("--no-rollout", action="store_true")
    args = p.parse_args()

    from ermrl.envs.host_groups import EnvGroup
    from ermrl.envs.mujoco_group import MujocoGroup

    rows, drifts = [], []
    for base_id in args.tasks:
        actions = action_sequence(base_id, args.slots, args.steps)
        kept = tuple(range(MujocoGroup(base_id, (0,), False, 0, 0).obs_dim))
        n = args.slots * args.steps
        gym_s, gym_packed = time_group(lambda: EnvGroup(base_id, kept, False, 0, args.slots), actions, args.repeats)
        rates = [n / gym_s]
        for threads in (1, 2):
            s, packed = time_group(lambda: MujocoGroup(base_id, kept, False, 0, args.slots, threads), actions,
                                   args.repeats)
            assert np.array_equal(packed, gym_packed), f"{base_id}: MujocoGroup differs from Gymnasium"
            rates.append(n / s)
        if not args.no_rollout:
            for threads in (1, 2):
                s, _ = time_group(lambda: RolloutStepper(base_id, args.slots, threads), actions, args.repeats)
                rates.append(n / s)
            drifts.append((base_id, rollout_drift(base_id, action_sequence(base_id, args.slots, 100))))
        rows.append((base_id, rates))

    head = ["task", "EnvGroup (Gymnasium)", "MujocoGroup t=1", "MujocoGroup t=2"]
    if not args.no_rollout:
        head += ["rollout t=1 (physics only, inexact)", "rollout t=2 (physics only, inexact)"]
    print(f"env-steps/s, {args.slots} slots, {args.steps} steps, median of {args.repeats}; "
          f"(x) = speed-up over EnvGroup\n")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for base_id, rates in rows:
        cells = [f"{rates[0]:,.0f}"] + [f"{r:,.0f} ({r / rates[0]:.2f}x)" for r in rates[1:]]
        print(f"| {base_id} | " + " | ".join(cells) + " |")
    if drifts:
        print("\nrollout (zero warm start per env step) vs exact physics, max |Δqpos| over the slots:\n")
        print("| task | after 1 step | after 10 steps | after 100 steps |\n|---|---|---|---|")
        for base_id, d in drifts:
            print(f"| {base_id} | " + " | ".join(f"{x:.1e}" for x in d) + " |")


if __name__ == "__main__":
    main()
