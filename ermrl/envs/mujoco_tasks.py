"""Gymnasium's v5 MuJoCo locomotion tasks, rewritten as batched functions over many envs of one task.

Each task is one :class:`TaskSpec` row of :data:`TASKS` (Gymnasium's default constructor arguments of the v5
class, its xml file and its registered ``max_episode_steps``) plus the functions of its family:

* :func:`x_position`: the position that the forward reward differentiates, read from one env's ``MjData``
  before and after the step (``qpos[0]``; Ant: ``xpos`` of its main body 1; Humanoid: the mass center).
* :func:`observe`: (n, obs_dim) float64 observations from the gathered ``MjData`` fields of n envs.
* :func:`reward_terminated`: the (n,) float64 rewards and (n,) bool ``terminated`` flags of a step.
* :func:`draw_reset_state`: one env's reset noise, drawn from its ``np_random`` as Gymnasium's ``reset_model``.

Exactness: every value equals Gymnasium's bit for bit. The batched forms only use elementwise IEEE operations
(subtraction, division, products with the same Python-float weights, clipping, comparisons) in the same order
as Gymnasium, and row sums ``np.sum(x, axis=1)`` of C-contiguous 2-D arrays, which NumPy computes with the same
pairwise inner loop as the 1-D ``np.sum(row)`` that Gymnasium calls per env (checked in the tests, float32 and
float64). The control cost keeps the dtype of the actions the caller passes, as Gymnasium's ``np.square(action)``
does (float32 actions give a float32 cost that is then promoted). Humanoid's mass center is an ``einsum`` whose
summation order is NumPy's business, so it is computed per env with Gymnasium's very expression.

What is *not* here: the physics (``mj_step`` and ``mj_rnePostConstraint``, in
:mod:`ermrl.envs.mujoco_group`), the info dicts, rendering, non-default constructor arguments and the v4 tasks.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

FAMILIES = ("half_cheetah", "hopper", "walker2d", "swimmer", "ant", "humanoid", "humanoid_standup")


@dataclass(frozen=True)
class TaskSpec:
    """The constants of one v5 task: Gymnasium's default constructor arguments, named as there."""

    base_id: str
    family: str
    """One of :data:`FAMILIES`: which observation / reward / health functions apply."""
    xml: str
    """File name under Gymnasium's ``envs/mujoco/assets`` (the v5 class's ``xml_file`` default)."""
    frame_skip: int
    skipped_qpos: int
    """How many leading qpos entries ``exclude_current_positions_from_observation=True`` leaves out (x or x, y)."""
    reset_noise_scale: float
    qvel_noise: str
    """"normal": qvel = init_qvel + scale · standard_normal(nv); "uniform": init_qvel + uniform(-scale, scale, nv)."""
    ctrl_cost_weight: float
    forward_reward_weight: float = 1.0
    healthy_reward: float = 0.0
    contact_cost_weight: float = 0.0
    """Ant's ``contact_cost_weight``, Humanoid's ``contact_cost_weight``, HumanoidStandup's ``impact_cost_weight``."""
    contact_force_range: tuple[float, float] | None = None
    """Ant: each cfrc_ext entry clipped to this range (observation and contact cost)."""
    contact_cost_range: tuple[float, float] | None = None
    """Humanoid / HumanoidStandup: the contact (impact) cost clipped to this range."""
    healthy_z_range: tuple[float, float] | None = None
    healthy_angle_range: tuple[float, float] | None = None
    healthy_state_range: tuple[float, float] | None = None
    qvel_obs_clip: float | None = None
    """Hopper / Walker2d: the observed qvel is clipped to [-clip, clip]."""
    terminate_when_unhealthy: bool = True
    max_episode_steps: int = 1000
    """Gymnasium's registered TimeLimit."""


TASKS: dict[str, TaskSpec] = {t.base_id: t for t in (
    TaskSpec("HalfCheetah-v5", "half_cheetah", "half_cheetah.xml", frame_skip=5, skipped_qpos=1,
             reset_noise_scale=0.1, qvel_noise="normal", ctrl_cost_weight=0.1, forward_reward_weight=1.0),
    TaskSpec("Hopper-v5", "hopper", "hopper.xml", frame_skip=4, skipped_qpos=1,
             reset_noise_scale=5e-3, qvel_noise="uniform", ctrl_cost_weight=1e-3, forward_reward_weight=1.0,
             healthy_reward=1.0, healthy_state_range=(-100.0, 100.0), healthy_z_range=(0.7, float("inf")),
             healthy_angle_range=(-0.2, 0.2), qvel_obs_clip=10.0),
    TaskSpec("Walker2d-v5", "walker2d", "walker2d_v5.xml", frame_skip=4, skipped_qpos=1,
             reset_noise_scale=5e-3, qvel_noise="uniform", ctrl_cost_weight=1e-3, forward_reward_weight=1.0,
             healthy_reward=1.0, healthy_z_range=(0.8, 2.0), healthy_angle_range=(-1.0, 1.0), qvel_obs_clip=10.0),
    TaskSpec("Swimmer-v5", "swimmer", "swimmer.xml", frame_skip=4, skipped_qpos=2,
             reset_noise_scale=0.1, qvel_noise="uniform", ctrl_cost_weight=1e-4, forward_reward_weight=1.0),
    TaskSpec("Ant-v5", "ant", "ant.xml", frame_skip=5, skipped_qpos=2,
             reset_noise_scale=0.1, qvel_noise="normal", ctrl_cost_weight=0.5, forward_reward_weight=1,
             healthy_reward=1.0, contact_cost_weight=5e-4, contact_force_range=(-1.0, 1.0),
             healthy_z_range=(0.2, 1.0)),
    TaskSpec("Humanoid-v5", "humanoid", "humanoid.xml", frame_skip=5, skipped_qpos=2,
             reset_noise_scale=1e-2, qvel_noise="uniform", ctrl_cost_weight=0.1, forward_reward_weight=1.25,
             healthy_reward=5.0, contact_cost_weight=5e-7, contact_cost_range=(-np.inf, 10.0),
             healthy_z_range=(1.0, 2.0)),
    TaskSpec("HumanoidStandup-v5", "humanoid_standup", "humanoidstandup.xml", frame_skip=5, skipped_qpos=2,
             reset_noise_scale=1e-2, qvel_noise="uniform", ctrl_cost_weight=0.1, forward_reward_weight=1.0,
             contact_cost_weight=5e-7, contact_cost_range=(-np.inf, 10.0)),
)}

FIELDS: dict[str, tuple[str, ...]] = {
    "half_cheetah": ("qpos", "qvel"),
    "hopper": ("qpos", "qvel"),
    "walker2d": ("qpos", "qvel"),
    "swimmer": ("qpos", "qvel"),
    "ant": ("qpos", "qvel", "cfrc_ext"),
    "humanoid": ("qpos", "qvel", "cinert", "cvel", "qfrc_actuator", "cfrc_ext"),
    "humanoid_standup": ("qpos", "qvel", "cinert", "cvel", "qfrc_actuator", "cfrc_ext"),
}
"""The ``MjData`` arrays each family's observation, reward and health read after a step or reset."""


def task_spec(base_id: str) -> TaskSpec:
    """The :class:`TaskSpec` of a v5 id; a ValueError names the supported ids otherwise (v4 ids included:
    their xml files, observations and rewards differ from v5 and are not rewritten here)."""
    if base_id in TASKS:
        return TASKS[base_id]
    supported = ", ".join(TASKS)
    if base_id.rsplit("-", 1)[0] + "-v5" in TASKS:
        raise ValueError(f"{base_id!r}: only the v5 MuJoCo tasks are batched ({supported}); "
                         f"use {base_id.rsplit('-', 1)[0]}-v5 or the Gymnasium EnvGroup")
    raise ValueError(f"{base_id!r} is not a batched MuJoCo task; supported: {supported}")


def xml_path(spec: TaskSpec) -> str:
    """The xml file that Gymnasium's v5 class loads (``expand_model_path`` of its default ``xml_file``)."""
    import gymnasium

    return str(Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets" / spec.xml)


def dt(spec: TaskSpec, model) -> float:
    """Seconds per env step, as ``MujocoEnv.dt``: ``model.opt.timestep * frame_skip``."""
    return model.opt.timestep * spec.frame_skip


def obs_dim(spec: TaskSpec, model) -> int:
    """Length of the raw (unmasked) observation."""
    n = model.nq - spec.skipped_qpos + model.nv
    if spec.family == "ant":
        n += (model.nbody - 1) * 6
    elif spec.family in ("humanoid", "humanoid_standup"):
        n += (model.nbody - 1) * (10 + 6 + 6) + model.nv - 6
    return n


# -- one env: the forward position, the reset noise ------------------------------------------------------------

def x_position(spec: TaskSpec, model, data, body_mass_sum: float | None = None) -> float:
    """The x coordinate whose change over the step, divided by dt, is the forward velocity. Gymnasium
    differences an (x, y) pair for Swimmer, Ant and Humanoid; the x component of that elementwise difference is
    the same number. HumanoidStandup has no forward term (returns 0.0).

    Humanoid: ``mass_center`` = ``einsum('b,bj->j', body_mass, xipos) / body_mass.sum()``, evaluated per env with
    that exact expression (a batched einsum could sum in another order)."""
    family = spec.family
    if family in ("half_cheetah", "hopper", "walker2d", "swimmer"):
        return data.qpos[0]
    if family == "ant":
        return data.xpos[1, 0]  # data.body(main_body=1).xpos
    if family == "humanoid":
        mass = model.body_mass
        denom = mass.sum() if body_mass_sum is None else body_mass_sum
        return (np.einsum("b,bj->j", mass, data.xipos) / denom)[0]
    return 0.0


def draw_reset_state(spec: TaskSpec, rng: np.random.Generator, init_qpos: np.ndarray, init_qvel: np.ndarray):
    """Gymnasium's ``reset_model`` draws: qpos noise first (uniform in ±scale, size nq), then qvel noise (scale ·
    standard normal for HalfCheetah and Ant, uniform in ±scale otherwise, size nv). Returns (qpos (nq,),
    qvel (nv,)) float64, to be written to ``MjData`` followed by ``mj_forward`` (``set_state``)."""
    noise_low = -spec.reset_noise_scale
    noise_high = spec.reset_noise_scale
    qpos = init_qpos + rng.uniform(low=noise_low, high=noise_high, size=init_qpos.size)
    if spec.qvel_noise == "normal":
        qvel = init_qvel + spec.reset_noise_scale * rng.standard_normal(init_qvel.size)
    else:
        qvel = init_qvel + rng.uniform(low=noise_low, high=noise_high, size=init_qvel.size)
    return qpos, qvel


# -- n envs: observation, reward, termination ------------------------------------------------------------------

def observe(spec: TaskSpec, f: dict[str, np.ndarray]) -> np.ndarray:
    """(n, obs_dim) float64 observations from the gathered fields ``f`` (each (n,) + the MjData array's shape):

    * HalfCheetah, Swimmer: qpos[skip:], qvel.
    * Hopper, Walker2d: qpos[1:], clip(qvel, -10, 10).
    * Ant: qpos[2:], qvel, clip(cfrc_ext[1:], -1, 1) flattened (13·6).
    * Humanoid, HumanoidStandup: qpos[2:], qvel, cinert[1:] (13·10), cvel[1:] (13·6), qfrc_actuator[6:],
      cfrc_ext[1:] (13·6), unclipped."""
    qpos, qvel = f["qpos"], f["qvel"]
    n = len(qpos)
    position = qpos[:, spec.skipped_qpos:]
    if spec.qvel_obs_clip is not None:
        qvel = np.clip(qvel, -spec.qvel_obs_clip, spec.qvel_obs_clip)
    parts = [position, qvel]
    if spec.family == "ant":
        low, high = spec.contact_force_range
        parts.append(np.clip(f["cfrc_ext"][:, 1:], low, high).reshape(n, -1))
    elif spec.family in ("humanoid", "humanoid_standup"):
        parts += [f["cinert"][:, 1:].reshape(n, -1), f["cvel"][:, 1:].reshape(n, -1),
                  f["qfrc_actuator"][:, 6:], f["cfrc_ext"][:, 1:].reshape(n, -1)]
    return np.concatenate(parts, axis=1)


def healthy(spec: TaskSpec, f: dict[str, np.ndarray]) -> np.ndarray | None:
    """(n,) bool ``is_healthy`` of each env, or None for the tasks without one (HalfCheetah, Swimmer,
    HumanoidStandup).

    * Hopper: -100 < each of state_vector()[2:] (qpos[2:], qvel) < 100, 0.7 < qpos[1] < inf, -0.2 < qpos[2] < 0.2.
    * Walker2d: 0.8 < qpos[1] < 2, -1 < qpos[2] < 1.
    * Ant: every qpos, qvel finite and 0.2 <= qpos[2] <= 1 (inclusive, as Gymnasium's Ant).
    * Humanoid: 1 < qpos[2] < 2."""
    qpos, qvel = f["qpos"], f["qvel"]
    family = spec.family
    if family in ("hopper", "walker2d"):
        z, angle = qpos[:, 1], qpos[:, 2]
        min_z, max_z = spec.healthy_z_range
        min_angle, max_angle = spec.healthy_angle_range
        ok = (min_z < z) & (z < max_z) & (min_angle < angle) & (angle < max_angle)
        if spec.healthy_state_range is not None:
            min_state, max_state = spec.healthy_state_range
            state = np.concatenate([qpos, qvel], axis=1)[:, 2:]
            ok &= np.all((min_state < state) & (state < max_state), axis=1)
        return ok
    if family == "ant":
        min_z, max_z = spec.healthy_z_range
        finite = np.isfinite(qpos).all(axis=1) & np.isfinite(qvel).all(axis=1)
        return finite & (min_z <= qpos[:, 2]) & (qpos[:, 2] <= max_z)
    if family == "humanoid":
        min_z, max_z = spec.healthy_z_range
        return (min_z < qpos[:, 2]) & (qpos[:, 2] < max_z)
    return None


def control_cost(spec: TaskSpec, actions: np.ndarray) -> np.ndarray:
    """(n,) ``ctrl_cost_weight · Σ action²`` in the actions' dtype (float32 actions: a float32 cost, as
    Gymnasium's ``np.sum(np.square(action))``). Humanoid and HumanoidStandup square ``data.ctrl`` instead, which
    is the action cast to float64 (MuJoCo clamps ctrl internally, not in ``data.ctrl``)."""
    if spec.family in ("humanoid", "humanoid_standup"):
        actions = np.asarray(actions, np.float64)
    return spec.ctrl_cost_weight * np.sum(np.square(actions), axis=1)


def reward_terminated(spec: TaskSpec, x_before: np.ndarray, x_after: np.ndarray, step_dt: float, timestep: float,
                      actions: np.ndarray, f: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The (n,) float64 rewards and (n,) bool ``terminated`` of a step, from x positions (n,) before and after
    it, the (n, nu) actions as passed to the envs, and the fields ``f`` gathered after it. Gymnasium's order:

    * HalfCheetah, Swimmer: w_f · v_x - ctrl_cost.
    * Hopper, Walker2d: (w_f · v_x + healthy · h) - ctrl_cost.
    * Ant: (v_x · w_f + healthy · h) - (ctrl_cost + w_c · Σ clip(cfrc_ext, -1, 1)²).
    * Humanoid: (w_f · v_x + healthy · h) - (ctrl_cost + clip(w_c · Σ cfrc_ext², -inf, 10)), v_x of the mass center.
    * HumanoidStandup: qpos[2] / timestep - ctrl_cost - clip(w_c · Σ cfrc_ext², -inf, 10) + 1.

    ``terminated`` = not healthy (``terminate_when_unhealthy``); False for the tasks without a health check."""
    n = len(actions)
    family = spec.family
    ctrl_cost = control_cost(spec, actions)
    ok = healthy(spec, f)
    terminated = np.zeros(n, bool) if ok is None else (~ok if spec.terminate_when_unhealthy else np.zeros(n, bool))
    if family == "humanoid_standup":
        uph_cost = (f["qpos"][:, 2] - 0) / timestep
        impact = spec.contact_cost_weight * np.sum(np.square(f["cfrc_ext"].reshape(n, -1)), axis=1)
        impact = np.clip(impact, *spec.contact_cost_range)
        return uph_cost - ctrl_cost - impact + 1, terminated
    x_velocity = (x_after - x_before) / step_dt
    if family == "ant":
        forward_reward = x_velocity * spec.forward_reward_weight
    else:
        forward_reward = spec.forward_reward_weight * x_velocity
    if ok is None:  # HalfCheetah, Swimmer
        return forward_reward - ctrl_cost, terminated
    rewards = forward_reward + ok * spec.healthy_reward
    if family in ("hopper", "walker2d"):
        return rewards - ctrl_cost, terminated
    if family == "ant":
        low, high = spec.contact_force_range
        contact = np.clip(f["cfrc_ext"], low, high).reshape(n, -1)
        contact_cost = spec.contact_cost_weight * np.sum(np.square(contact), axis=1)
    else:  # humanoid
        contact_cost = spec.contact_cost_weight * np.sum(np.square(f["cfrc_ext"].reshape(n, -1)), axis=1)
        contact_cost = np.clip(contact_cost, *spec.contact_cost_range)
    return rewards - (ctrl_cost + contact_cost), terminated
