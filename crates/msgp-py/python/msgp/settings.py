"""The settings a fit and a learning loop take, as types: ``Msgp(settings=...)`` overrides
fields of ``msgp.defaults("fit", method=...)``, and these ``TypedDict``\\ s name every field
of each method, with its type (a type checker then catches a misspelt or misplaced one; at run
time a field of another method is refused by name). ``MsgpFitSettings`` for
``method="msgp"``, ``OneStepFitSettings`` for ``"gp-narx"`` and ``"pilco-narx"``,
``LinearKfFitSettings`` for ``"linear-kf"``. ``learn_policy(env=..., settings=...)`` takes
``LearnerSettings`` (over ``msgp.defaults("learner")``, whose ``fit`` is a ``FitSettings``
resolved as ``Msgp``'s), ``learn_policy(settings=...)`` on the built-in pendulum
``PendulumLearnSettings`` (over ``msgp.defaults("learn")``). The keys are those of the Rust
settings (a test compares them)."""

from typing import Dict, List, Literal, Optional, TypedDict, Union

__all__ = [
    "Integrator",
    "Recipe",
    "Segments",
    "MsgpFitSettings",
    "OneStepFitSettings",
    "LinearKfFitSettings",
    "FitSettings",
    "Excitation",
    "PolicySearchSettings",
    "LearnerSettings",
    "PendulumLearnSettings",
]

Mean = Literal["zero", "linear"]
Complexity = Literal["pseudo-data-nll", "half-log-det", "neg-half-log-det", "none"]
NoiseStart = Literal["split", "full"]
Solver = Literal["adam", "lbfgs"]
OneStepObjective = Literal["exact", "vfe"]


class _Integrator(TypedDict):
    output: int
    order: int


class Integrator(_Integrator, total=False):
    """An output that integrates (``msgp fit --integrating OUTPUT:ORDER[:linear]``): output
    ``output`` is a pure integrator of order ``order`` (1 or 2) of the others; ``linear``: its
    GP is switched off, the linear mean carries it."""

    linear: bool


class Recipe(TypedDict):
    """An MSGP training recipe (``alternative``): prior mean, complexity term, Adam step and
    noise start."""

    mean: Mean
    complexity: Complexity
    learning_rate: float
    noise_start: NoiseStart


class Segments(TypedDict):
    """Training by segments of a long log: ``length`` predicted steps each, ``batch`` of them
    per Adam step (``msgp fit --segment-length``)."""

    length: int
    batch: int


class _Shared(TypedDict, total=False):
    ly: int
    """Output lags of the window."""
    lu: int
    """Input lags of the window."""
    seed: int
    """Seed of every random choice."""
    integrators: List[Integrator]
    """Outputs that integrate (``msgp fit --integrating``)."""


class MsgpFitSettings(_Shared, total=False):
    """The MSGP fit's own fields (``msgp fit --method msgp``)."""

    inducing: int
    mean: Mean
    complexity: Complexity
    likelihood: Literal["free-run", "filter"]
    iterations: int
    """Most Adam steps of the early-stopped head training."""
    full_data_iterations: Optional[int]
    """Length of the final training on all the data (``msgp fit --iters``); None: none."""
    learning_rate: float
    optimizer: Solver
    noise_floor: float
    noise_start: NoiseStart
    start: Literal["one-step", "spread", "linear-kf"]
    start_window: Union[Literal["measured"], Dict[str, Dict[str, int]]]
    """Where a measured trajectory's rollout starts: "measured" (the paper's), or
    ``{"smoothed": {"samples": n, "degree": d}}``."""
    alternative: Optional[Recipe]
    """The recipe raced against the settings' own on the validation tail; None: none."""
    validation_fraction: float
    eval_every: int
    patience: int
    frozen: List[Literal["PseudoInputs", "PseudoTargets", "Lengthscales", "SignalVar",
                         "ProcessNoise", "ObsNoise", "LinearMean"]]
    one_step_iterations: int
    one_step_solver: Solver
    one_step_objective: OneStepObjective
    calibrate: bool
    blow_up_fallback: bool
    full_data_blow_up: float
    segments: Optional[Segments]


class OneStepFitSettings(_Shared, total=False):
    """A one-step GP-NARX fit's own fields (``--method gp-narx`` or ``pilco-narx``)."""

    inducing: int
    mean: Mean
    iterations: int
    solver: Solver
    objective: OneStepObjective


class LinearKfFitSettings(_Shared, total=False):
    """The linear Kalman-filter model's own fields (``--method linear-kf``)."""

    iterations: int


FitSettings = Union[MsgpFitSettings, OneStepFitSettings, LinearKfFitSettings]
"""The settings ``Msgp(settings=...)`` takes, by method."""


class Excitation(TypedDict, total=False):
    """The random episodes' multisine, relative to each command's range."""

    components: int
    min_hz: float
    max_hz: float
    rms_fraction: float
    """Root-mean-square of each command as a fraction of half its range."""


class PolicySearchSettings(TypedDict, total=False):
    """The policy search on the model's predicted rollouts."""

    iterations: int
    learning_rate: float
    restarts: int
    restart_spread: float
    seed: int
    candidates: int
    candidate_spread: float
    candidate_starts: int
    trust_region: float
    solver: Solver


class _LoopSettings(TypedDict, total=False):
    iterations: int
    random_rollouts: int
    seed: int
    fit: FitSettings
    search: PolicySearchSettings
    evaluation_episodes: int
    prequential_choice: bool
    """Search on the GP model only while it predicts unseen episodes better than its linear
    part (MSGP only)."""
    ff_segment: Optional[int]
    warm_start: Optional[int]


class LearnerSettings(_LoopSettings, total=False):
    """The loop on a plant or Gymnasium environment (``learn_policy(env=..., settings=...)``)."""

    excitation: Excitation
    search_from_first: bool


class PendulumExcitation(TypedDict, total=False):
    """The built-in pendulum's random excitation."""

    components: int
    min_hz: float
    max_hz: float
    rms: float


class PendulumLearnSettings(_LoopSettings, total=False):
    """The loop on the built-in pendulum (``learn_policy(settings=...)`` without ``env``)."""

    excitation: PendulumExcitation
    episode_seconds: float
    policy_horizon_seconds: float
    cost_widths: List[float]
    gain_scale: List[float]
