"""MujocoGroup against Gymnasium's v5 envs (through EnvGroup, which encodes the same-step autoreset): packed
steps, snapshots and cross-restores must be equal bit for bit."""

import numpy as np
import pytest

from ermrl.envs import mujoco_tasks
from ermrl.envs.host_groups import EnvGroup, EpisodeRecord, ReplayMismatch, Stepped, make_gymnasium
from ermrl.envs.mujoco_group import MujocoGroup

# base id: (slots, steps, threads). Never-ending tasks cross the 1000-step TimeLimit; the others fall under
# actions up to 1.5x the control range (MuJoCo clamps ctrl, the control cost does not).
CASES = {
    "HalfCheetah-v5": (3, 1010, 2),
    "Swimmer-v5": (3, 1010, 1),
    "Hopper-v5": (4, 500, 1),
    "Walker2d-v5": (4, 500, 2),
    "Ant-v5": (3, 600, 2),
    "Humanoid-v5": (3, 400, 2),
    "HumanoidStandup-v5": (2, 1005, 1),
}
DROPPED = (1, 3)  # masked-out observation dims, so that kept_dims is exercised


def kept_for(base_id: str) -> tuple[int, ...]:
    env = make_gymnasium(base_id)
    dim = env.observation_space.shape[0]
    env.close()
    return tuple(i for i in range(dim) if i not in DROPPED)


def random_actions(group: MujocoGroup, rng: np.random.Generator, n: int, dtype=np.float32,
                   poison: bool = False) -> np.ndarray:
    space = group.action_space
    actions = rng.uniform(1.5 * space.low, 1.5 * space.high, size=(n, group.nu)).astype(dtype)
    if poison or rng.random() < 0.02:  # a diverged policy now and then: EnvGroup's nan_to_num
        actions[rng.integers(n), rng.integers(group.nu)] = rng.choice([np.nan, np.inf, -np.inf])
    return actions


def assert_same_records(a: list[EpisodeRecord], b: list[EpisodeRecord]):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.start == y.start
        assert x.actions.dtype == y.actions.dtype and np.array_equal(x.actions, y.actions)
        assert x.obs.dtype == y.obs.dtype == np.float64 and np.array_equal(x.obs, y.obs)


@pytest.mark.parametrize("base_id", list(CASES))
def test_matches_gymnasium_bit_for_bit(base_id):
    slots, steps, threads = CASES[base_id]
    kept = kept_for(base_id)
    d = len(kept)
    gym_group = EnvGroup(base_id, kept, False, 4, slots)
    group = MujocoGroup(base_id, kept, False, 4, slots, threads=threads)
    seeds = np.arange(slots) + 11
    first = group.reset(seeds)
    expected = gym_group.reset(seeds)
    assert first.dtype == np.float32 and first.shape == (slots, d)
    assert np.array_equal(first, expected)
    assert_same_records(group.snapshot(), gym_group.snapshot())

    rng = np.random.default_rng(7)
    ends = truncations = terminations = 0
    for t in range(steps):
        actions = random_actions(group, rng, slots, poison=t == 3)
        packed = group.step(actions)
        packed_gym = gym_group.step(actions)
        assert packed.dtype == np.float32 and packed.shape == (slots, 2 * d + 3)
        assert np.array_equal(packed, packed_gym), f"step {t}"
        s = Stepped.unpack(packed, d)
        ends += int(np.sum(s.terminated | s.truncated))
        terminations += int(np.sum(s.terminated))
        truncations += int(np.sum(s.truncated))
        if t == steps // 2:
            assert_same_records(group.snapshot(), gym_group.snapshot())
    assert ends > 0, "the run must cross at least one auto-reset"
    if base_id in ("HalfCheetah-v5", "Swimmer-v5", "HumanoidStandup-v5"):
        assert truncations == slots and terminations == 0
    else:
        assert terminations > 0

    records = group.snapshot()
    assert_same_records(records, gym_group.snapshot())
    assert any("rng" in r.start for r in records)

    # cross-restores: MujocoGroup -> MujocoGroup (other thread count), MujocoGroup -> EnvGroup,
    # EnvGroup -> MujocoGroup; all continue exactly as the originals.
    current = np.stack([r.obs for r in records]).astype(np.float32)[:, list(kept)]
    restored = MujocoGroup(base_id, kept, False, 4, slots, threads=3 - threads)
    restored_gym = EnvGroup(base_id, kept, False, 4, slots)
    restored_from_gym = MujocoGroup(base_id, kept, False, 4, slots, threads=threads)
    assert np.array_equal(restored.restore(records), current)
    assert np.array_equal(restored_gym.restore(records), current)
    assert np.array_equal(restored_from_gym.restore(gym_group.snapshot()), current)
    for other in (restored, restored_gym, restored_from_gym):
        assert_same_records(other.snapshot(), records)
    for t in range(20):
        actions = random_actions(group, rng, slots)
        packed = group.step(actions)
        for other in (restored, restored_gym, restored_from_gym, gym_group):
            assert np.array_equal(other.step(actions), packed), f"step {t} after restore"
    for g in (group, gym_group, restored, restored_gym, restored_from_gym):
        g.close()


FLOAT64_STEPS = {"HalfCheetah-v5": 150, "Swimmer-v5": 150, "Hopper-v5": 150, "Walker2d-v5": 150, "Ant-v5": 150,
                 "Humanoid-v5": 100, "HumanoidStandup-v5": 60}


@pytest.mark.parametrize("base_id", list(FLOAT64_STEPS))
def test_float64_rewards_and_observations(base_id):
    """The packed array is float32; here the float64 rewards and final observations are compared with raw
    Gymnasium envs (driven with EnvGroup's autoreset), so that a last-bit difference cannot hide in the cast."""
    slots = 2
    envs = [make_gymnasium(base_id) for _ in range(slots)]
    group = MujocoGroup(base_id, (0,), False, 0, slots, threads=2)
    group.reset(np.array([21, 22]))
    for i, env in enumerate(envs):
        env.reset(seed=21 + i)
    rng = np.random.default_rng(5)
    for t in range(FLOAT64_STEPS[base_id]):
        actions = random_actions(group, rng, slots, poison=t == 3)
        group.step(actions)
        actions = np.nan_to_num(actions, nan=0.0, posinf=0.0, neginf=0.0)  # as EnvGroup does
        for i, env in enumerate(envs):
            obs, reward, terminated, truncated, _ = env.step(actions[i])
            assert reward == group.last_reward[i], (t, i)
            assert np.array_equal(obs, group.last_final_obs[i]), (t, i)
            if terminated or truncated:
                env.reset()
            assert np.array_equal(env.unwrapped._get_obs(), group.snapshot()[i].obs)
    group.close()


@pytest.mark.parametrize("base_id", ["Hopper-v5", "Walker2d-v5", "Ant-v5", "Humanoid-v5"])
def test_health_thresholds(base_id):
    """``healthy`` against Gymnasium's ``is_healthy`` on states at and around every threshold."""
    spec = mujoco_tasks.task_spec(base_id)
    env = make_gymnasium(base_id)
    u = env.unwrapped
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    z_index, angle_index = (1, 2) if base_id in ("Hopper-v5", "Walker2d-v5") else (2, None)
    edges = [v for r in (spec.healthy_z_range, spec.healthy_angle_range) if r for v in r if np.isfinite(v)]
    values = [e + k for e in edges for k in (-1e-9, 0.0, 1e-9)] + [0.5, 1.5, np.nan]
    qpos0, qvel0 = u.init_qpos, u.init_qvel
    states = []
    for value in values:
        for index in (z_index, angle_index):
            if index is not None:
                qpos = qpos0.copy()
                qpos[index] = value
                states.append((qpos, qvel0 + rng.normal(0, 1, qvel0.shape)))
    qpos = qpos0.copy()
    qpos[z_index] = 0.9 * spec.healthy_z_range[0] + 0.1 * min(spec.healthy_z_range[1], 3.0)
    for big in (99.0, 100.0, np.inf, np.nan):  # Hopper's state range, Ant's finiteness
        qvel = qvel0.copy()
        qvel[-1] = big
        states.append((qpos, qvel))
    expected = []
    for qpos, qvel in states:
        u.data.qpos[:], u.data.qvel[:] = qpos, qvel
        expected.append(bool(u.is_healthy))
    f = {"qpos": np.stack([s[0] for s in states]), "qvel": np.stack([s[1] for s in states])}
    assert mujoco_tasks.healthy(spec, f).tolist() == expected
    assert 0 < sum(expected) < len(expected)
    env.close()


def test_float64_actions_and_reset_semantics():
    """float64 actions take the float64 control-cost path; re-seeding resets the step count and generator."""
    for base_id in ("HalfCheetah-v5", "Ant-v5"):
        kept = kept_for(base_id)
        gym_group, group = EnvGroup(base_id, kept, False, 0, 2), MujocoGroup(base_id, kept, False, 0, 2)
        rng = np.random.default_rng(3)
        for seeds in ([5, 6], [6, 5]):
            assert np.array_equal(group.reset(np.array(seeds)), gym_group.reset(np.array(seeds)))
            for t in range(25):
                actions = random_actions(group, rng, 2, np.float64)
                assert np.array_equal(group.step(actions), gym_group.step(actions)), (base_id, t)
        assert_same_records(group.snapshot(), gym_group.snapshot())
        group.close()
        gym_group.close()


def test_replay_mismatch_and_bad_arguments():
    kept = kept_for("HalfCheetah-v5")
    group = MujocoGroup("HalfCheetah-v5", kept, False, 10, 2)
    with pytest.raises(RuntimeError):
        group.step(np.zeros((2, 6), np.float32))
    group.reset(np.array([1, 2]))
    rng = np.random.default_rng(0)
    for _ in range(5):
        group.step(random_actions(group, rng, 2))
    records = group.snapshot()
    tampered = list(records)
    tampered[1] = EpisodeRecord(records[1].start, records[1].actions, records[1].obs + 1e-12)
    with pytest.raises(ReplayMismatch, match="slot 11"):
        MujocoGroup("HalfCheetah-v5", kept, False, 10, 2).restore(tampered)
    tampered = [EpisodeRecord({"seed": 3}, records[0].actions, records[0].obs), records[1]]
    with pytest.raises(ReplayMismatch, match="slot 10"):
        MujocoGroup("HalfCheetah-v5", kept, False, 10, 2).restore(tampered)
    # a Hopper episode replayed past its fall ends early
    hopper_kept = kept_for("Hopper-v5")
    hopper = MujocoGroup("Hopper-v5", hopper_kept, False, 0, 1)
    hopper.reset(np.array([0]))
    falling = np.full((400, 3), 1.0)
    with pytest.raises(ReplayMismatch, match="ended early"):
        hopper.restore([EpisodeRecord({"seed": 0}, falling, np.zeros(11))])
    with pytest.raises(ValueError, match="v5"):
        MujocoGroup("Ant-v4", kept, False, 0, 1)
    with pytest.raises(ValueError, match="not a batched MuJoCo task"):
        MujocoGroup("CartPole-v1", (0,), True, 0, 1)
    with pytest.raises(ValueError, match="discrete"):
        MujocoGroup("Ant-v5", (0,), True, 0, 1)


FAMILY_ATTRS = {  # TaskSpec field -> the v5 class's attribute holding the same default
    "ctrl_cost_weight": "_ctrl_cost_weight", "forward_reward_weight": "_forward_reward_weight",
    "healthy_reward": "_healthy_reward", "contact_cost_weight": "_contact_cost_weight",
    "contact_force_range": "_contact_force_range", "contact_cost_range": "_contact_cost_range",
    "healthy_z_range": "_healthy_z_range", "healthy_angle_range": "_healthy_angle_range",
    "healthy_state_range": "_healthy_state_range", "reset_noise_scale": "_reset_noise_scale",
    "terminate_when_unhealthy": "_terminate_when_unhealthy",
}


@pytest.mark.parametrize("base_id", list(CASES))
def test_task_table_is_gymnasiums_defaults(base_id):
    import gymnasium

    spec = mujoco_tasks.task_spec(base_id)
    env = make_gymnasium(base_id)
    u = env.unwrapped
    assert env.spec.max_episode_steps == spec.max_episode_steps and env.spec.kwargs == {}
    assert u.frame_skip == spec.frame_skip and u.fullpath == mujoco_tasks.xml_path(spec)
    assert u._exclude_current_positions_from_observation
    for field, attr in FAMILY_ATTRS.items():
        if hasattr(u, attr):
            assert getattr(spec, field) == getattr(u, attr), field
    if base_id == "HumanoidStandup-v5":
        assert (u._impact_cost_weight, u._impact_cost_range) == (spec.contact_cost_weight, spec.contact_cost_range)
        assert u._uph_cost_weight == 1
    group = MujocoGroup(base_id, (0,), False, 0, 1)
    assert group.obs_dim == env.observation_space.shape[0]
    assert group.action_space == env.action_space
    assert isinstance(group.action_space, gymnasium.spaces.Box)
    env.close()
    group.close()


def test_row_sums_equal_gymnasiums_per_env_sums():
    """The batched costs rely on np.sum(x, axis=1) of a C-contiguous array equalling np.sum(row) per row."""
    rng = np.random.default_rng(1)
    for dtype in (np.float32, np.float64):
        for width in (2, 3, 6, 8, 17, 84):
            x = (rng.standard_normal((65, width)) * rng.choice([1e-3, 1.0, 1e3], (65, width))).astype(dtype)
            batched = np.sum(np.square(x), axis=1)
            assert all(batched[i] == np.sum(np.square(x[i])) for i in range(len(x)))
