"""PILCO with MSGP models on a Gymnasium environment.

``msgp.learn_policy(env=...)`` runs the loop of ``msgp_core::learner`` on any environment with a
continuous ``Box`` action space: it calls ``env.reset(seed=...)`` and ``env.step(action)``
itself, with the environment's own code (nothing of it is copied into msgp). The observation
vector is the model's output; the cost is PILCO's saturating cost of the distance to a
``target``, each output on the scale of its width (``None``: the output does not count); an
output named in ``angles`` is costed on the tip of a unit pole at that angle.

Two forms::

    result = msgp.learn_policy(env=gym.make("Pendulum-v1"), seed=0)   # a known task
    result = msgp.learn_policy(env=my_env, target=[...], widths=[...], seed=0, iterations=5)

Known tasks are in ``TASKS`` (plain dicts: read one, copy it, change it, pass its entries).
The result's ``policy`` acts on an observation (``result.policy(obs) -> action``, inside the
action bounds) and saves and loads (``msgp.Policy.load(path)``); ``iterations`` are the
per-iteration reports, ``episodes`` every episode run (observations, actions, the
environment's return). Ctrl-C, an exception raised by the environment or by ``progress`` stop
the loop within one model fit and are raised as they were, with the run so far in the
exception's ``partial`` attribute (a ``LearnResult``).
"""

import numpy as np

from . import _msgp

#: Tasks msgp knows, by Gymnasium id. Each entry holds the arguments of ``learn_policy``.
TASKS = {
    # The pole's tip is (sin θ, cos θ) for a unit pole, so PILCO's cost on the tip's distance to
    # upright is the saturating cost of (cos θ − 1, sin θ) with equal widths; the angular
    # velocity does not count. Observation: [cos θ, sin θ, θ̇], torque in [−2, 2], dt 0.05 s.
    # The observation is the whole state, so the model's window is one step (history 1, 1).
    # Episodes start at any angle: the search's rollouts start from each of the latest 8
    # episodes' starts. 1 random episode + 14 policy episodes of 100 steps: 75 s of
    # interaction, 1500 steps.
    "Pendulum-v1": {
        "target": [1.0, 0.0, 0.0],
        "widths": [0.5, 0.5, None],
        "episode_steps": 100,
        "policy_horizon": 100,
        "policy": {"kind": "rbf", "basis": 50},
        "separate_starts": 8,
        "iterations": 14,
        "settings": {"fit": {"ly": 1, "lu": 1}},
    },
}


#: Observation bounds at least this large are taken as no bound.
_HUGE = 1e6


def _flat(observation, what):
    values = np.asarray(observation, dtype=float)
    if values.ndim != 1:
        raise _msgp.InvalidInputError(
            f"{what} returned an observation of shape {values.shape}; msgp needs a flat vector"
        )
    return values.tolist()


class _GymPlant:
    """The environment as msgp's plant: ``reset(seed) -> obs``, ``step(u) -> (obs,
    terminated, truncated)`` (a truncated episode's missing steps are not costed as failures);
    every episode's return is logged (seed, return) in the order run."""

    def __init__(self, env):
        self.env = env
        self.space = env.action_space
        self.log = []

    def reset(self, seed):
        observation, _info = self.env.reset(seed=int(seed))
        self.log.append([int(seed), 0.0])
        return _flat(observation, "env.reset")

    def step(self, command):
        action = np.asarray(command, dtype=self.space.dtype).reshape(self.space.shape)
        observation, reward, terminated, truncated, _info = self.env.step(action)
        if self.log:
            self.log[-1][1] += float(reward)
        return _flat(observation, "env.step"), bool(terminated), bool(truncated)


def _bounds(space, what):
    low = np.asarray(space.low, dtype=float).ravel()
    high = np.asarray(space.high, dtype=float).ravel()
    if len(low) != len(high):
        raise _msgp.InvalidInputError(f"{what}: low and high differ in size")
    return low, high


def plant_spec(env, period=None, angles=()):
    """The plant spec msgp reads from ``env``: its ``Box`` action space's bounds, its
    observation space's size and bounds, and the control period (``period``, else
    ``env.unwrapped.dt``, else 1 / ``metadata["render_fps"]``, else 1 s). ``angles``: the
    indices of observation entries that are angles in radians (costed on a unit pole's tip:
    ``target`` is then an angle and a full turn is the target again)."""
    actions = env.action_space
    kind = type(actions).__name__
    if kind != "Box":
        raise _msgp.InvalidInputError(
            f"the environment's action space is {actions!r} ({kind}); msgp learns policies "
            "for a continuous Box action space"
        )
    low, high = _bounds(actions, "action space")
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise _msgp.InvalidInputError(
            f"the action space {actions!r} is unbounded; msgp needs finite action bounds"
        )
    shape = getattr(env.observation_space, "shape", None)
    if shape is None or len(shape) != 1:
        raise _msgp.InvalidInputError(
            f"the observation space {env.observation_space!r} is not a flat Box; msgp needs a "
            "vector of outputs"
        )
    olow, ohigh = _bounds(env.observation_space, "observation space")
    if period is None:
        period = getattr(env.unwrapped, "dt", None)
    if period is None:
        fps = (getattr(env, "metadata", None) or {}).get("render_fps")
        period = 1.0 / fps if fps else 1.0
    angles = set(angles)
    bad = [j for j in angles if not (isinstance(j, int) and 0 <= j < shape[0])]
    if bad:
        raise _msgp.InvalidInputError(
            f"angles {bad} are not indices of the observation's {shape[0]} entries"
        )
    outputs = []
    for j in range(shape[0]):
        out = {"name": f"obs{j}", "angle": j in angles}
        # a bound of float32's size (CartPole's velocities) says "unbounded"
        if abs(olow[j]) < _HUGE and abs(ohigh[j]) < _HUGE:
            out["low"], out["high"] = float(olow[j]), float(ohigh[j])
        outputs.append(out)
    commands = [
        {"name": f"action{i}", "low": float(lo), "high": float(hi)}
        for i, (lo, hi) in enumerate(zip(low, high))
    ]
    return {"period": float(period), "commands": commands, "outputs": outputs}


class LearnResult:
    """What a run produced: ``policy`` (a ``msgp.Policy``), ``iterations`` (one report per
    policy iteration, each with the mean environment return of its evaluation episodes as
    ``evaluation_return``), ``episodes`` (every interaction episode: ``outputs``,
    ``commands``, ``return``, ``seed``, ``ended_early``, the ``policy`` kind or None for a
    random one), ``settings`` and ``task``."""

    def __init__(self, raw, task, log):
        self.policy = raw["policy"]
        self.settings = raw["settings"]
        self.task = task
        self.iterations = list(raw["iterations"])
        self.episodes = list(raw["episodes"])
        returns = {}
        for seed, ret in log:
            returns.setdefault(seed, ret)
        for e in self.episodes:
            e["return"] = returns.get(e["seed"])
        # the evaluation episodes of iteration k run right after its own episode
        n = self.settings.get("evaluation_episodes", 0)
        policy_seeds = [e["seed"] for e in self.episodes if e["policy"] is not None]
        position = 0
        for report, seed in zip(self.iterations, policy_seeds):
            at = next((i for i in range(position, len(log)) if log[i][0] == seed), None)
            if at is None:
                break
            evaluation = [r for _, r in log[at + 1 : at + 1 + n]]
            report["evaluation_return"] = float(np.mean(evaluation)) if evaluation else None
            position = at + 1 + n

    def __repr__(self):
        return (
            f"LearnResult({len(self.iterations)} iterations, {len(self.episodes)} episodes, "
            f"policy={self.policy!r})"
        )


def _task_of(env, target, widths, options, iterations):
    env_id = getattr(getattr(env, "spec", None), "id", None)
    known = TASKS.get(env_id, {}) if target is None else {}
    if target is None and not known:
        raise _msgp.InvalidInputError(
            f"msgp knows no task for the environment {env_id!r} (known: "
            f"{', '.join(sorted(TASKS))}); pass target=[...] and widths=[...]"
        )
    if target is not None and widths is None:
        raise _msgp.InvalidInputError("target needs widths (one per output; None: not counted)")

    def given(value, key, default):
        return value if value is not None else known.get(key, default)

    steps = given(options["episode_steps"], "episode_steps", 100)
    task = {
        "target": list(given(target, "target", [])),
        "widths": list(given(widths, "widths", [])),
        "episode_steps": steps,
        "policy_horizon": given(options["policy_horizon"], "policy_horizon", steps),
        "width_scales": list(given(options["width_scales"], "width_scales", [1.0])),
        "policy": given(options["policy"], "policy", {"kind": "rbf", "basis": 30}),
    }
    starts = given(options["separate_starts"], "separate_starts", None)
    if starts is not None:
        task["separate_starts"] = starts
    return task, given(iterations, "iterations", 10), known.get("settings", {})


def _merged(base, over):
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def learn_policy(
    env,
    *,
    seed=0,
    target=None,
    widths=None,
    iterations=None,
    episode_steps=None,
    policy_horizon=None,
    policy=None,
    separate_starts=None,
    width_scales=None,
    angles=None,
    period=None,
    settings=None,
    method="msgp",
    likelihood=None,
    progress=None,
):
    """PILCO on ``env`` (see the module docs). ``policy``: ``{"kind": "rbf", "basis": N}`` or
    ``{"kind": "linear"}``; ``separate_starts=k``: the search's rollouts start from each of
    the latest ``k`` episodes' first observations (for episodes that start anywhere), by
    default from one Gaussian over them; ``width_scales``: PILCO's several widths, the cost
    the mean of the saturating costs at the widths times each scale (``[1, 4]``: a wide
    cost's slope far from the target, the widths' precision near it); ``angles``: indices of observation entries that are
    angles (radians), costed on a unit pole's tip (``plant_spec``); ``settings`` overrides the loop's defaults
    (``msgp_core::learner::LearnerSettings``; a known task's own settings first);
    ``method`` (``"msgp"``, ``"gp-narx"``: one-step, standard PILCO; ``"linear-kf"``) and, for
    ``"msgp"``, ``likelihood`` (``"filter"``, the default's, or ``"free-run"``) then choose the
    model, derived from those settings as ``msgp reproduce plant-task --models`` derives it;
    ``progress`` is called with each iteration's report."""
    spec = plant_spec(env, period, angles or ())
    options = {
        "episode_steps": episode_steps,
        "policy_horizon": policy_horizon,
        "policy": policy,
        "separate_starts": separate_starts,
        "width_scales": width_scales,
    }
    task, iterations, preset = _task_of(env, target, widths, options, iterations)
    overrides = _merged(preset, dict(settings or {}))
    overrides.setdefault("iterations", iterations)
    plant = _GymPlant(env)
    try:
        raw = _msgp.learn_on_plant(
            plant,
            spec,
            task,
            settings=overrides,
            method=method,
            likelihood=likelihood,
            seed=seed,
            progress=progress,
        )
    except BaseException as err:
        partial = getattr(err, "partial", None)
        if isinstance(partial, dict):
            err.partial = LearnResult(partial, task, plant.log)
        raise
    return LearnResult(raw, task, plant.log)
