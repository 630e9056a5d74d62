"""Gymnasium envs stepped on the host, in the main process or in worker processes.

An :class:`EnvGroup` owns a contiguous range of env *slots* (slot = agent · n_envs + env) and steps them with
Gymnasium's same-step autoreset semantics: when an episode ends, ``step`` returns the reset observation as
``obs`` and the observation that ended the episode as ``final_obs``, exactly as the JAX backend does.

Gymnasium's ``AsyncVectorEnv`` runs one process per env, which costs more than a MuJoCo step on a 2-core
machine with dozens of agents; here each worker process holds a whole group of envs instead.

A group also keeps, per env, how its running episode began (the reset's seed, or the state of the env's
``np_random`` before an automatic reset) and the actions taken since. ``snapshot`` returns that record, and
``restore`` rebuilds the same envs elsewhere (a later process) by resetting them the same way and replaying the
actions. It works for any env whose dynamics depend only on its ``np_random`` and its actions (Box2D, MuJoCo,
classic control), and it checks itself: the replayed observation must equal the recorded one, bit for bit.
"""

from __future__ import annotations

import sys
import warnings
from multiprocessing.connection import Connection
from typing import NamedTuple

import numpy as np

from ermrl.child_interpreter import ChildDied, ChildInterpreter


class Stepped(NamedTuple):
    """One step of B envs, unpacked from the (B, 2·obs_dim + 3) float32 array that groups return
    (columns: obs, final_obs, reward, terminated, truncated). One array crosses the process pipe and the
    host-to-JAX boundary instead of five. ``unpack`` works on NumPy and JAX arrays with any leading axes."""

    obs: np.ndarray
    """(..., obs_dim) float32 masked observation to act on next (the reset one if the episode ended)."""
    final_obs: np.ndarray
    """(..., obs_dim) float32 masked observation reached by the step, before any reset."""
    reward: np.ndarray
    """(...,) float32."""
    terminated: np.ndarray
    """(...,) bool."""
    truncated: np.ndarray
    """(...,) bool, False when the step also terminated."""

    @staticmethod
    def unpack(packed, obs_dim: int) -> "Stepped":
        d = obs_dim
        return Stepped(packed[..., :d], packed[..., d:2 * d], packed[..., 2 * d],
                       packed[..., 2 * d + 1] > 0.5, packed[..., 2 * d + 2] > 0.5)


def make_gymnasium(base_id: str):
    """``gymnasium.make`` without the passive checker (it costs a few µs a step), warnings silenced."""
    import gymnasium as gym

    if "mujoco" in str(gym.spec(base_id).entry_point):
        _quiet_mujoco()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(base_id, disable_env_checker=True)


def _quiet_mujoco():
    """MuJoCo 4 warns on stderr, at every model load, that Gymnasium's XML uses the deprecated
    'settotalmass'; that one message is dropped, every other MuJoCo warning still printed."""
    try:
        import mujoco
    except ImportError:  # no [mujoco] extra: gym.make raises DependencyNotInstalled, which names it
        return

    def warn(message: str):
        if "settotalmass" not in message:
            print(f"MuJoCo warning: {message}", file=sys.stderr)

    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(warn)


class EpisodeRecord(NamedTuple):
    """How one env reached its current state: enough to rebuild it in another process."""

    start: dict
    """{"seed": int} for a seeded reset, {"rng": the bit generator's state} for an automatic one (JSON-ready)."""
    actions: np.ndarray
    """(t,) int64 or (t, dim) float64: the actions taken since that reset."""
    obs: np.ndarray
    """(raw_obs_dim,) float64: the env's current, unmasked observation, to check the replay against."""


class ReplayMismatch(RuntimeError):
    """A replayed env did not come back to its recorded observation: its dynamics depend on more than its seed
    and actions, so the run cannot be resumed exactly."""


class EnvGroup:
    """The envs of slots [first, first + size), all of one base id."""

    def __init__(self, base_id: str, kept_dims: tuple[int, ...], discrete: bool, first: int, size: int):
        self.first, self.size = first, size
        self.kept = np.asarray(kept_dims)
        self.discrete = discrete
        self.envs = [make_gymnasium(base_id) for _ in range(size)]
        self._starts: list[dict] = [{} for _ in range(size)]
        self._actions: list[list] = [[] for _ in range(size)]
        self._obs: list = [None] * size

    def _mask(self, obs) -> np.ndarray:
        return np.asarray(obs, np.float32)[self.kept]

    def _began(self, i: int, start: dict, obs) -> None:
        self._starts[i], self._actions[i], self._obs[i] = start, [], obs

    def reset(self, seeds: np.ndarray) -> np.ndarray:
        """Seeds and resets every env of the group: seeds (size,) -> (size, obs_dim) masked observations."""
        out = []
        for i, (env, seed) in enumerate(zip(self.envs, seeds)):
            obs = env.reset(seed=int(seed))[0]
            self._began(i, {"seed": int(seed)}, obs)
            out.append(self._mask(obs))
        return np.stack(out)

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Steps every env: actions (size,) int or (size, dim) float. Returns the packed (size, 2·obs_dim + 3)
        :class:`Stepped`. Non-finite Box actions (a diverged policy) are replaced by 0 so that the simulator
        survives; training reports the divergence."""
        d = len(self.kept)
        out = np.zeros((self.size, 2 * d + 3), np.float32)
        if not self.discrete:
            actions = np.nan_to_num(actions, nan=0.0, posinf=0.0, neginf=0.0)
        for i, env in enumerate(self.envs):
            action = int(actions[i]) if self.discrete else actions[i]
            o, r, term, trunc, _ = env.step(action)
            out[i, d:2 * d] = np.asarray(o)[self.kept]
            out[i, 2 * d:] = r, term, trunc and not term
            if term or trunc:
                start = {"rng": env.unwrapped.np_random.bit_generator.state}
                o, _ = env.reset()
                self._began(i, start, o)
            else:
                self._actions[i].append(action if self.discrete else np.array(action))
                self._obs[i] = o
            out[i, :d] = np.asarray(o)[self.kept]
        return out

    def snapshot(self) -> list[EpisodeRecord]:
        """One :class:`EpisodeRecord` per env of the group, in slot order."""
        if self.discrete:
            as_actions = lambda a: np.asarray(a, np.int64).reshape(len(a))
        else:
            shape = self.envs[0].action_space.shape
            as_actions = lambda a: np.asarray(a, np.float64).reshape((len(a),) + shape)
        return [EpisodeRecord(start, as_actions(actions), np.asarray(obs, np.float64))
                for start, actions, obs in zip(self._starts, self._actions, self._obs)]

    def restore(self, records: list[EpisodeRecord]) -> np.ndarray:
        """Brings every env to the state a :meth:`snapshot` recorded (in any process), by resetting it as its
        episode began and replaying the actions. Returns the (size, obs_dim) masked observations. Raises
        :class:`ReplayMismatch` when an env does not come back to the recorded observation."""
        out = []
        for i, (env, record) in enumerate(zip(self.envs, records)):
            if "seed" in record.start:
                obs = env.reset(seed=record.start["seed"])[0]
            else:
                env.unwrapped.np_random.bit_generator.state = record.start["rng"]
                obs = env.reset()[0]
            self._began(i, record.start, obs)
            for action in record.actions:
                action = int(action) if self.discrete else np.asarray(action, np.float32)
                obs, _, term, trunc, _ = env.step(action)
                if term or trunc:
                    raise ReplayMismatch(f"slot {self.first + i}: the replayed episode ended early")
                self._actions[i].append(action)
            self._obs[i] = obs
            if not np.array_equal(np.asarray(obs, np.float64), record.obs):
                raise ReplayMismatch(f"slot {self.first + i}: the replayed observation differs from the recorded one")
            out.append(self._mask(obs))
        return np.stack(out)

    def close(self):
        for env in self.envs:
            env.close()


def serve(fd: int):
    """Worker process loop on socket ``fd``: builds an EnvGroup from the first message, then answers
    ('reset'|'step'|'close', *args) messages."""
    conn = Connection(fd)
    group = EnvGroup(*conn.recv())
    conn.send("ready")
    while True:
        command, *payload = conn.recv()
        if command == "close":
            group.close()
            conn.close()
            return
        try:
            conn.send(("ok", getattr(group, command)(*payload)))
        except Exception as error:  # report to the main process, which raises it
            conn.send(("error", f"{type(error).__name__}: {error}"))


class WorkerGroup:
    """An EnvGroup living in its own process (a :class:`~ermrl.child_interpreter.ChildInterpreter`);
    ``send``/``receive`` split a call so groups step in parallel."""

    def __init__(self, *args):
        self.first, self.size = args[3], args[4]
        self.child = ChildInterpreter("ermrl.envs.host_groups", "an env worker process")
        self.child.send(args)
        try:
            ready = self.child.receive()
        except ChildDied:
            ready = None
        if ready != "ready":
            raise RuntimeError("an env worker process failed to start; see its error above")

    def send(self, command: str, *payload):
        self.child.send((command, *payload))

    def receive(self):
        status, value = self.child.receive()
        if status == "error":
            raise (ReplayMismatch if value.startswith(ReplayMismatch.__name__) else RuntimeError)(f"env worker: {value}")
        return value

    def close(self):
        self.child.close(("close",))
