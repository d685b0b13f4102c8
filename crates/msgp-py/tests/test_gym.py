"""PILCO on Gymnasium environments, run with their own code: the Pendulum-v1 preset, a second
environment in the target form, the learned policy (acting, saving, loading), and what a bad
environment or an interruption gets."""

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import msgp

# a short budget: three iterations of 3 s episodes, five evaluation episodes each
SHORT = dict(iterations=3, episode_steps=60, policy_horizon=60, settings={"evaluation_episodes": 5})


def summary(result):
    return [
        (r["predicted_cost"], r["actual_cost"], r["expected_cost"], r["evaluation_return"])
        for r in result.iterations
    ]


def test_pendulum_v1_preset_learns_and_repeats():
    """With nothing but the environment and a seed msgp knows the task; over a short budget
    the evaluation return (five 60-step episodes) is finite and improves (−383, −188, −165 at
    this seed: the first search on the linear model, the next two on the GP model, the
    linear competitor's filter failing on the data at the second); the same seed gives the
    same numbers and the same policy."""
    result = msgp.learn_policy(env=gym.make("Pendulum-v1"), seed=0, **SHORT)
    assert result.task["target"] == [1.0, 0.0, 0.0]
    assert len(result.iterations) == 3 and len(result.episodes) == 4
    returns = [r["evaluation_return"] for r in result.iterations]
    assert all(np.isfinite(returns)), returns
    assert returns[-1] > returns[0] + 100, returns
    assert [r["search_model"] for r in result.iterations[1:]] == ["gp", "gp"]
    assert all(np.isfinite(e["return"]) for e in result.episodes)
    assert result.episodes[0]["policy"] is None and result.episodes[1]["policy"] == "rbf"
    assert result.episodes[1]["outputs"].shape == (61, 3)
    again = msgp.learn_policy(env=gym.make("Pendulum-v1"), seed=0, **SHORT)
    assert summary(again) == summary(result)
    obs = np.array([0.0, 1.0, 0.5])
    assert np.array_equal(again.policy(obs), result.policy(obs))
    # the preset is a plain dict a user can read and copy
    assert msgp.gym.TASKS["Pendulum-v1"]["widths"] == [0.5, 0.5, None]


def test_a_second_environment_in_the_target_form():
    """MountainCarContinuous-v0, unmodified, with a target and widths and a linear policy:
    the loop runs, its actions stay inside the action bounds."""
    env = gym.make("MountainCarContinuous-v0")
    result = msgp.learn_policy(
        env=env,
        target=[0.45, 0.0],
        widths=[0.3, None],
        seed=1,
        iterations=1,
        episode_steps=50,
        policy={"kind": "linear"},
        settings={"evaluation_episodes": 2},
    )
    assert result.policy.kind == "linear"
    assert np.isfinite(result.iterations[0]["actual_cost"])
    obs, _ = env.reset(seed=3)
    for _ in range(20):
        action = result.policy(obs)
        assert action.shape == (1,) and -1.0 <= action[0] <= 1.0
        obs, *_ = env.step(action.astype(np.float32))


def test_the_policy_saves_and_loads_and_refuses_other_versions(tmp_path):
    result = msgp.learn_policy(
        env=gym.make("Pendulum-v1"), seed=2, iterations=1, episode_steps=30,
        settings={"evaluation_episodes": 0},
    )
    path = tmp_path / "policy.json"
    result.policy.save(path)
    loaded = msgp.Policy.load(path)
    for obs in ([1.0, 0.0, 0.0], [-1.0, 0.0, 2.0], [0.6, -0.8, -4.0]):
        assert np.array_equal(loaded(np.array(obs)), result.policy(np.array(obs)))
        assert -2.0 <= loaded(np.array(obs))[0] <= 2.0
    doc = json.loads(path.read_text())
    assert doc["format"] == "msgp-policy" and doc["format_version"].startswith("1.")
    assert doc["task"]["widths"] == [0.5, 0.5, None]
    assert doc["plant"]["period"] == 0.05
    doc["format_version"] = "2.0"
    other = tmp_path / "future.json"
    other.write_text(json.dumps(doc))
    with pytest.raises(msgp.ModelFileError, match="format version 2.0 is not supported"):
        msgp.Policy.load(other)
    with pytest.raises(msgp.InvalidInputError, match="3 outputs"):
        loaded(np.zeros(4))
    with pytest.raises(msgp.InvalidInputError):
        loaded(np.array([0.0, np.nan, 0.0]))


class Faulty(gym.Env):
    """A 2-output, 1-action environment that misbehaves at step `at` of an episode as `how`
    says ("raise": at its `at`-th step in all)."""

    def __init__(self, how, at=5):
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(2,))
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,))
        self.how, self.at, self.k, self.total, self.x = how, at, 0, 0, np.zeros(2)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.k, self.x = 0, self.np_random.normal(0.0, 0.1, size=2)
        return self.x.astype(np.float32), {}

    def step(self, action):
        self.k += 1
        self.total += 1
        self.x = 0.9 * self.x + 0.1 * float(action[0])
        obs = self.x.copy()
        if self.total == self.at and self.how == "raise":
            raise RuntimeError("the robot's emergency stop")
        if self.k == self.at and self.how == "nan":
            obs[1] = np.nan
        if self.k == self.at and self.how == "shape":
            obs = np.zeros(3)
        return obs, 0.0, False, False, {}


TARGET = dict(target=[0.5, 0.0], widths=[0.5, None], episode_steps=20, iterations=2)


def test_bad_environments_get_clear_errors():
    with pytest.raises(msgp.InvalidInputError, match="Discrete"):
        msgp.learn_policy(env=gym.make("CartPole-v1"), target=[0, 0, 0, 0], widths=[1, 1, 1, 1])
    with pytest.raises(msgp.InvalidInputError, match="knows no task"):
        msgp.learn_policy(env=Faulty("none"))
    with pytest.raises(msgp.MsgpError, match="step 5: output 1 .* NaN"):
        msgp.learn_policy(env=Faulty("nan"), **TARGET)
    with pytest.raises(msgp.MsgpError, match="step 5: the observation has 3 values"):
        msgp.learn_policy(env=Faulty("shape"), **TARGET)
    with pytest.raises(msgp.InvalidInputError, match="2 outputs"):
        msgp.learn_policy(env=Faulty("none"), target=[0.5], widths=[0.5], iterations=1)
    with pytest.raises(msgp.InvalidInputError, match=r"angles \[2\] are not indices"):
        msgp.learn_policy(env=Faulty("none"), angles=[2], **TARGET)


def test_method_and_likelihood_choose_the_loop_model():
    # as `msgp reproduce plant-task --models` derives them from the preset: the settings the
    # run reports say which model was fitted, and only MSGP keeps the prequential choice
    fitted = {}
    for method, likelihood in [("gp-narx", None), ("linear-kf", None), ("msgp", "free-run")]:
        result = msgp.learn_policy(
            env=Faulty("none"), method=method, likelihood=likelihood, **TARGET
        )
        fit = result.settings["fit"]
        fitted[method] = (fit["method"], fit.get("likelihood"), result.settings["prequential_choice"])
    assert fitted == {
        "gp-narx": ("GpNarx", None, False),
        "linear-kf": ("LinearKf", None, False),
        "msgp": ("Msgp", "free-run", True),
    }
    default = msgp.learn_policy(env=Faulty("none"), **TARGET).settings["fit"]
    assert (default["method"], default["likelihood"]) == ("Msgp", "filter")
    with pytest.raises(msgp.InvalidInputError, match='unknown likelihood "exact"'):
        msgp.learn_policy(env=Faulty("none"), likelihood="exact", **TARGET)
    with pytest.raises(msgp.InvalidInputError, match='method "gp-narx" has its own'):
        msgp.learn_policy(env=Faulty("none"), method="gp-narx", likelihood="filter", **TARGET)
    with pytest.raises(msgp.InvalidInputError, match='"pilco-narx" is not a model of the learning loop'):
        msgp.learn_policy(env=Faulty("none"), method="pilco-narx", **TARGET)
    with pytest.raises(msgp.InvalidInputError, match='unknown method "bogus"'):
        msgp.learn_policy(env=Faulty("none"), method="bogus", **TARGET)
    with pytest.raises(msgp.InvalidInputError, match="params belong to the built-in"):
        msgp.learn_policy(env=Faulty("none"), params={"lag": 0.0}, **TARGET)


def test_a_time_limit_truncates_without_costing_a_failure():
    # the environment's own limit (10 steps) ends every episode before the task's 20: each
    # is truncated, not failed, and the loop runs on
    env = gym.wrappers.TimeLimit(Faulty("none"), max_episode_steps=10)
    result = msgp.learn_policy(env=env, **TARGET)
    assert result.episodes and all(e["ended_early"] and e["truncated"] for e in result.episodes)


def test_an_angle_output_is_costed_on_its_tip_and_kept_in_the_policy_file(tmp_path):
    # a full turn from the target is the target: the first policy's recorded task says which
    # output is an angle, and the spec flags it
    spec = msgp.gym.plant_spec(Faulty("none"), angles=[0])
    assert [o["angle"] for o in spec["outputs"]] == [True, False]
    result = msgp.learn_policy(env=Faulty("none"), angles=[0], **TARGET)
    path = tmp_path / "policy.json"
    result.policy.save(str(path))
    assert json.loads(path.read_text())["task"]["angles"] == [True, False]


def test_an_environment_exception_stops_the_loop_and_keeps_the_episodes():
    """The environment fails in the first policy episode: its exception comes out as it was,
    the random episode run before it is kept in `partial`."""
    env = Faulty("raise", at=25)  # the random episode has 20 steps
    with pytest.raises(RuntimeError, match="emergency stop") as caught:
        msgp.learn_policy(env=env, seed=0, **TARGET)
    partial = caught.value.partial
    assert len(partial.episodes) == 1 and partial.episodes[0]["policy"] is None
    assert partial.iterations == []


def test_ctrl_c_stops_within_the_loop_and_keeps_the_run():
    """A KeyboardInterrupt (here raised by `progress` after the first iteration, where Ctrl-C
    would arrive) stops the loop; both episodes run so far are kept."""

    def interrupt(report):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as caught:
        msgp.learn_policy(env=Faulty("none"), seed=0, progress=interrupt, **TARGET)
    partial = caught.value.partial
    assert len(partial.iterations) == 1 and len(partial.episodes) == 2
