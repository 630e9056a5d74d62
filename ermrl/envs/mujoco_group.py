"""A batched, bit-exact stand-in for :class:`~ermrl.envs.host_groups.EnvGroup` on Gymnasium's v5 MuJoCo tasks.

:class:`MujocoGroup` keeps one ``mujoco.MjModel`` per group, loaded from the xml file that Gymnasium's v5
class loads, and one ``mujoco.MjData`` per env slot. A step makes, per env, exactly the MuJoCo calls of
Gymnasium's ``MujocoEnv.do_simulation`` in the same order (``data.ctrl[:] = action``,
``mj_step(model, data, nstep=frame_skip)``, ``mj_rnePostConstraint``: Gymnasium calls it after every step of
every task, and it costs under 1 µs, so it is kept for all, not only for the tasks whose observation reads
``cfrc_ext``), so the float64 physics, including the solver warm start (``qacc_warmstart``) that each MjData
carries from step to step, is Gymnasium's bit for bit. The observations, rewards and health checks are then
computed for all envs at once by :mod:`ermrl.envs.mujoco_tasks`, with the same values as Gymnasium's.

With ``threads > 1`` the slots are split into ``threads`` contiguous chunks whose physics runs on a persistent
thread pool (``mj_step`` releases the GIL); the results do not depend on ``threads``.

Why not ``mujoco.rollout``: it takes and returns ``mjSTATE_FULLPHYSICS`` states, which do not hold
``qacc_warmstart``; ``initial_warmstart`` can be passed in, but the warm start a rollout ends with is not
returned, so each env step after the first starts from another warm start than Gymnasium's and the physics
drifts (measured with 64 envs and a zero warm start per env step: max |Δqpos| 1e-15 to 1e-8 after 10 env
steps, 1e-3 to 0.2 after 100). It also returns none of the ``xpos``/``xipos``/``cinert``/``cvel``/
``qfrc_actuator``/``cfrc_ext`` of the last substep, which Ant's and Humanoid's observations and rewards read.
For the physics alone it is about 10 % faster on 1 thread than this group's per-env loop (HalfCheetah, Ant);
see ``benchmarks/mujoco_backend.py``.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ermrl.envs import mujoco_tasks as tasks
from ermrl.envs.host_groups import EpisodeRecord, ReplayMismatch, _quiet_mujoco


class MujocoGroup:
    """The envs of slots [first, first + size), all of one v5 MuJoCo base id; same protocol as ``EnvGroup``.

    Args:
        base_id: a v5 id of :data:`ermrl.envs.mujoco_tasks.TASKS` (v4 ids raise ValueError).
        kept_dims: indices of the raw observation kept in the returned (masked) observations.
        discrete: must be False (MuJoCo actions are Box).
        first, size: the slots of the group.
        threads: physics threads (1: the calling thread only).
    """

    def __init__(self, base_id: str, kept_dims: tuple[int, ...], discrete: bool, first: int, size: int,
                 threads: int = 1):
        import mujoco

        self.spec = tasks.task_spec(base_id)
        if discrete:
            raise ValueError(f"{base_id!r} has Box actions; a MujocoGroup cannot be discrete")
        if int(threads) < 1:
            raise ValueError(f"threads must be >= 1, not {threads}")
        self._mj = mujoco
        self.base_id = base_id
        self.first, self.size = first, size
        self.discrete = False
        self.threads = int(threads)
        _quiet_mujoco()
        self.model = mujoco.MjModel.from_xml_path(tasks.xml_path(self.spec))
        self.datas = [mujoco.MjData(self.model) for _ in range(size)]
        probe = self.datas[0] if size else mujoco.MjData(self.model)
        self.init_qpos = probe.qpos.ravel().copy()  # as MujocoEnv: the freshly made MjData's qpos (= qpos0)
        self.init_qvel = probe.qvel.ravel().copy()
        self.nu = self.model.nu
        self.obs_dim = tasks.obs_dim(self.spec, self.model)
        self.kept = np.asarray(kept_dims, dtype=np.int64).reshape(-1)
        if self.kept.size and (self.kept.min() < -self.obs_dim or self.kept.max() >= self.obs_dim):
            raise ValueError(f"kept_dims {tuple(kept_dims)} do not fit {base_id}'s {self.obs_dim}-dim observation")
        self.dt = tasks.dt(self.spec, self.model)
        self.timestep = self.model.opt.timestep
        self.max_steps = self.spec.max_episode_steps
        self._mass_sum = self.model.body_mass.sum()
        self._fields = tasks.FIELDS[self.spec.family]
        self._f = {name: np.zeros((size,) + getattr(probe, name).shape) for name in self._fields}
        self._views = [tuple(getattr(d, name) for name in self._fields) for d in self.datas]
        self._x = np.zeros(size)
        """Each slot's current forward position (``tasks.x_position`` of its MjData, set after every step and
        reset): the next step's "before" position, as MjData does not change between steps."""
        self._rngs: list[np.random.Generator | None] = [None] * size
        self._starts: list[dict] = [{} for _ in range(size)]
        self._elapsed = np.zeros(size, np.int64)
        """Steps since each slot's reset (TimeLimit's count), = the number of recorded actions."""
        self._actions = np.zeros((size, self.max_steps, self.nu))
        """The float64 actions taken since each slot's reset (the first ``_elapsed[i]`` rows of slot i)."""
        self._obs = np.zeros((size, self.obs_dim))
        """Each slot's current raw float64 observation."""
        self.last_reward = np.zeros(size)
        """(size,) float64 rewards of the last ``step``, before the packed array's float32 cast (diagnostics)."""
        self.last_final_obs = np.zeros((size, self.obs_dim))
        """(size, obs_dim) float64 raw observations reached by the last ``step``, before any reset (diagnostics)."""
        self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="mujoco-group") if self.threads > 1 else None

    @property
    def action_space(self):
        """The Box that Gymnasium's ``MujocoEnv`` builds from ``actuator_ctrlrange`` (float32)."""
        from gymnasium import spaces

        low, high = self.model.actuator_ctrlrange.copy().astype(np.float32).T
        return spaces.Box(low=low, high=high, dtype=np.float32)

    # -- physics, per env ----------------------------------------------------------------------------------------

    def _gather(self, i: int) -> None:
        for row, view in zip(self._f.values(), self._views[i]):
            row[i] = view

    def _step_chunk(self, slots: np.ndarray, actions: np.ndarray) -> None:
        """Steps the envs of ``slots`` with ``actions`` (len(slots), nu) and records their x positions and fields:
        Gymnasium's ``do_simulation`` calls, one env after the other."""
        mj, model, spec, frame_skip = self._mj, self.model, self.spec, self.spec.frame_skip
        for i, action in zip(slots, actions):
            data = self.datas[i]
            data.ctrl[:] = action
            mj.mj_step(model, data, nstep=frame_skip)
            mj.mj_rnePostConstraint(model, data)
            self._x[i] = tasks.x_position(spec, model, data, self._mass_sum)
            self._gather(i)

    def _physics(self, slots: np.ndarray, actions: np.ndarray) -> None:
        """Steps ``slots`` in ``threads`` contiguous chunks: the pool's threads take all but the last, which this
        thread steps meanwhile (one hand-over fewer per step)."""
        if self._pool is None or len(slots) < 2:
            self._step_chunk(slots, actions)
            return
        chunks = min(self.threads, len(slots))
        bounds = [len(slots) * k // chunks for k in range(chunks + 1)]
        futures = [self._pool.submit(self._step_chunk, slots[a:b], actions[a:b])
                   for a, b in zip(bounds[:-2], bounds[1:-1])]
        self._step_chunk(slots[bounds[-2]:], actions[bounds[-2]:])
        for future in futures:
            future.result()

    def _advance(self, slots: np.ndarray, actions: np.ndarray):
        """One env step of ``slots``: returns raw obs (n, obs_dim) float64, rewards (n,) float64, terminated (n,)
        bool, truncated (n,) bool (TimeLimit's, also where terminated)."""
        x_before = self._x[slots]
        self._physics(slots, actions)
        f = {name: a[slots] for name, a in self._f.items()}
        obs = tasks.observe(self.spec, f)
        reward, terminated = tasks.reward_terminated(self.spec, x_before, self._x[slots], self.dt, self.timestep,
                                                     actions, f)
        self._elapsed[slots] += 1
        truncated = self._elapsed[slots] >= self.max_steps
        return obs, reward, terminated, truncated

    def _reset_slots(self, slots) -> None:
        """Gymnasium's ``MujocoEnv.reset`` after the seeding, per slot: ``mj_resetData``, the reset noise from the
        slot's generator, ``set_state`` (qpos, qvel, ``mj_forward``); then the observations of those slots."""
        mj, model = self._mj, self.model
        slots = np.asarray(slots, np.int64)
        for i in slots:
            data = self.datas[i]
            mj.mj_resetData(model, data)
            qpos, qvel = tasks.draw_reset_state(self.spec, self._rngs[i], self.init_qpos, self.init_qvel)
            data.qpos[:] = qpos
            data.qvel[:] = qvel
            mj.mj_forward(model, data)
            self._x[i] = tasks.x_position(self.spec, model, data, self._mass_sum)
            self._gather(i)
        self._elapsed[slots] = 0
        if len(slots):
            self._obs[slots] = tasks.observe(self.spec, {name: a[slots] for name, a in self._f.items()})

    def _rng_from_state(self, state: dict) -> np.random.Generator:
        rng = np.random.Generator(np.random.PCG64(0))
        rng.bit_generator.state = state
        return rng

    # -- EnvGroup's protocol ---------------------------------------------------------------------------------------

    def _mask(self, obs: np.ndarray) -> np.ndarray:
        return np.asarray(obs, np.float32)[..., self.kept]

    def reset(self, seeds: np.ndarray) -> np.ndarray:
        """Seeds and resets every env of the group: seeds (size,) -> (size, obs_dim) masked float32 observations.
        Each slot's generator is ``gymnasium.utils.seeding.np_random(seed)``, as ``Env.reset(seed=...)``."""
        from gymnasium.utils import seeding

        seeds = [int(s) for s in np.asarray(seeds).reshape(-1)]
        if len(seeds) != self.size:
            raise ValueError(f"{len(seeds)} seeds for a group of {self.size} envs")
        for i, seed in enumerate(seeds):
            self._rngs[i] = seeding.np_random(seed)[0]
            self._starts[i] = {"seed": seed}
        self._reset_slots(np.arange(self.size))
        return self._mask(self._obs)

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Steps every env: actions (size, dim) float. Returns the packed (size, 2·obs_dim + 3) float32
        :class:`~ermrl.envs.host_groups.Stepped`; an ended episode (terminated, or truncated at the TimeLimit) is
        reset at once without a seed, continuing the slot's generator. Non-finite actions are replaced by 0."""
        if any(rng is None for rng in self._rngs):
            raise RuntimeError("MujocoGroup.step before reset() or restore()")
        if not np.isfinite(actions).all():  # a diverged policy: the simulator survives, training reports it
            actions = np.nan_to_num(actions, nan=0.0, posinf=0.0, neginf=0.0)
        if actions.shape != (self.size, self.nu):
            raise ValueError(f"actions of shape {actions.shape}; expected {(self.size, self.nu)}")
        slots = np.arange(self.size)
        obs, reward, terminated, truncated = self._advance(slots, actions)
        self.last_reward, self.last_final_obs = reward, obs
        d = len(self.kept)
        out = np.zeros((self.size, 2 * d + 3), np.float32)
        out[:, d:2 * d] = obs[:, self.kept]
        out[:, 2 * d] = reward
        out[:, 2 * d + 1] = terminated
        out[:, 2 * d + 2] = truncated & ~terminated
        ended = terminated | truncated
        going = np.flatnonzero(~ended)
        self._actions[going, self._elapsed[going] - 1] = actions[going]
        self._obs[going] = obs[going]
        ended = np.flatnonzero(ended)
        for i in ended:
            self._starts[i] = {"rng": self._rngs[i].bit_generator.state}
        self._reset_slots(ended)
        out[:, :d] = self._obs[:, self.kept]
        return out

    def snapshot(self) -> list[EpisodeRecord]:
        """One :class:`~ermrl.envs.host_groups.EpisodeRecord` per env of the group, in slot order."""
        return [EpisodeRecord(dict(self._starts[i]), self._actions[i, :self._elapsed[i]].copy(), self._obs[i].copy())
                for i in range(self.size)]

    def restore(self, records: list[EpisodeRecord]) -> np.ndarray:
        """Brings every env to the state a ``snapshot`` (of a MujocoGroup or an EnvGroup) recorded, by resetting it
        as its episode began and replaying its actions (cast to float32, as EnvGroup replays them; all slots
        step together). Returns the (size, obs_dim) masked observations. Raises
        :class:`~ermrl.envs.host_groups.ReplayMismatch`, naming the first slot that ended early or did not come back
        to the recorded observation."""
        from gymnasium.utils import seeding

        if len(records) != self.size:
            raise ValueError(f"{len(records)} records for a group of {self.size} envs")
        replays = []
        for i, record in enumerate(records):
            if "seed" in record.start:
                self._rngs[i] = seeding.np_random(record.start["seed"])[0]
            else:
                self._rngs[i] = self._rng_from_state(record.start["rng"])
            self._starts[i] = record.start
            replays.append(np.asarray(record.actions, np.float32).reshape(-1, self.nu))
        self._reset_slots(np.arange(self.size))
        lengths = np.array([len(a) for a in replays])
        ended_early = np.zeros(self.size, bool)
        for t in range(int(lengths.max(initial=0))):
            slots = np.flatnonzero((lengths > t) & ~ended_early)
            if not len(slots):
                break
            actions = np.stack([replays[i][t] for i in slots])
            obs, _, terminated, truncated = self._advance(slots, actions)
            ended_early[slots] = terminated | truncated
            going = slots[~(terminated | truncated)]
            self._actions[going, t] = actions[~(terminated | truncated)]
            self._obs[going] = obs[~(terminated | truncated)]
        for i, record in enumerate(records):
            if ended_early[i]:
                raise ReplayMismatch(f"slot {self.first + i}: the replayed episode ended early")
            if not np.array_equal(self._obs[i], record.obs):
                raise ReplayMismatch(f"slot {self.first + i}: the replayed observation differs from the recorded one")
        return self._mask(self._obs)

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        self.datas = []
        self._views = []
