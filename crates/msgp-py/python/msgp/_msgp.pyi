"""Type stubs of the compiled module `msgp._msgp` (re-exported by `msgp`)."""

import os
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from .settings import FitSettings, LearnerSettings, PendulumLearnSettings

__version__: str

# One trajectory: an array (n, d) or (n,) (anything numpy turns into floats); several: a list
# of such arrays.
ArrayLike = npt.ArrayLike
Data = Union[ArrayLike, Sequence[np.ndarray]]
Array = npt.NDArray[np.float64]
PathLike = Union[str, "os.PathLike[str]"]
Gains = Union[str, Dict[str, Any], Sequence[float]]

class MsgpError(Exception):
    """Base class of every error raised by msgp."""

class InvalidInputError(MsgpError, ValueError):
    """Bad input: wrong shapes, non-finite values, too few samples for the history, unknown
    names or settings. Also a ValueError."""

class NumericalError(MsgpError):
    """A matrix indefinite even with the largest allowed jitter, or a non-finite value."""

class ModelFileError(MsgpError):
    """A model file that cannot be read, parsed, checked or written."""

class NotFittedError(MsgpError):
    """The model has neither been fitted nor loaded."""

class Msgp:
    """Gaussian-process dynamics model trained for long-term predictions (MSGP), or the
    one-step GP-NARX baselines ("gp-narx", "pilco-narx").

    history: (l_y, l_u), past outputs and inputs in the GP input; "auto": chosen by each fit
        on its training data alone (the first 80 % fits, the last 20 % judges: every history up
        to 10 lags as a linear model, then the best few and the equal ones (l, l) each fitted
        by the method itself and judged by their free simulation; the shortest within one
        standard error of the best) — `msgp fit --history auto`; one fit per judged candidate
        (minutes for MSGP). The choice is in `report["history_choice"]` and the model file.
    inducing: pseudo-inputs; None: min(100, training windows / 2).
    iterations: the most solver iterations of any one training (MSGP: of each training on
        the trajectory likelihood; without it the head's early-stopped run stops within 1000
        and the final training on all the data runs 400; baselines: L-BFGS on the one-step
        marginal likelihood, default 300; linear-kf: L-BFGS on the filter likelihood, default
        400) — `msgp fit --iters`.
    seed: seed of every random choice.
    settings: other fields of `defaults("fit", method=method)` to override (advanced; each
        method has its own, typed in `msgp.settings`: `MsgpFitSettings`, `OneStepFitSettings`,
        `LinearKfFitSettings`; a setting of another method is refused by name), e.g.
        `{"mean": "linear", "integrators": [{"output": 0, "order": 2}]}` declares output 0 a
        pure double integrator (`msgp fit --integrating 0:2`; add `"linear": True` for
        `0:2:linear`); `{"optimizer": "lbfgs"}` fits by L-BFGS (`msgp fit --optimizer lbfgs`).
    likelihood: of an MSGP fit, "free-run" (the paper's product of a free simulation's
        per-step marginals, the default) or "filter" (the joint density of the observations by
        the moment-matched filter) — `msgp fit --likelihood`; other methods refuse it.
    start: where an MSGP fit starts, "one-step" (the sparse GP-NARX fit, the default; where the
        zero-mean recipe's final training from it blows up, that recipe's fallback heads train,
        from the spread start and with a linear mean), "spread" (the one-step fit's starting
        point, not optimised) or "linear-kf" (the linear Kalman-filter
        model under a GP that starts at zero; implies the linear mean) — `msgp fit --start`.
    segment_length: an MSGP fit on a long log trains on segments of this many predicted steps,
        each started from the data, 2 per Adam step; 0: every trajectory whole; None: 1000
        when the training part has more than 4000 windows — `msgp fit --segment-length`.
    """

    def __init__(
        self,
        history: Union[Tuple[int, int], str] = (2, 2),
        inducing: Optional[int] = None,
        method: str = "msgp",
        seed: int = 0,
        iterations: Optional[int] = None,
        settings: Optional[FitSettings] = None,
        likelihood: Optional[str] = None,
        start: Optional[str] = None,
        segment_length: Optional[int] = None,
    ) -> None: ...
    def fit(
        self,
        u: Data,
        y: Data,
        *,
        input_names: Optional[Sequence[str]] = None,
        output_names: Optional[Sequence[str]] = None,
        progress: Optional[Callable[[Dict[str, Any]], Any]] = None,
    ) -> "Msgp":
        """Fits on inputs `u` and outputs `y` (arrays (n, d) or (n,), or lists of arrays for
        several trajectories); returns self. Releases the GIL. `progress` is called with a
        dict (stage, iteration, iterations, loss, validation, elapsed) after every training
        iteration of an MSGP fit; with history="auto", first with stage 0 after each candidate
        history judged (iteration: candidates judged, iterations: of how many, loss: its
        score, history: (l_y, l_u)); Ctrl-C or an exception it raises stops the fit and
        raises."""
    def simulate(
        self, u: ArrayLike, y_init: ArrayLike, *, rollout: str = "mm"
    ) -> Tuple[Array, Array]:
        """Free simulation driven by `u` (T samples) from the first max(l_y, l_u) rows of
        `y_init`; returns (mean, var), each (T − max(l_y, l_u), d_y), original units.
        rollout: "mm" (moment matching, the function's uncertainty correlated over time),
        "mm-independent" (the paper's moment matching) or "mean" (mean feedback) —
        `msgp simulate --rollout`."""
    def filtered(self, u: ArrayLike, y: ArrayLike) -> Tuple[Array, Array]:
        """One-step-ahead filtered predictions of the measured `u`, `y`: row i predicts sample
        max(l_y, l_u) + i given every measured output before it (`msgp simulate --filtered`);
        returns (mean, var), original units. Not a free simulation."""
    def score(
        self, u: Data, y: Data, *, rollout: str = "mm", filtered: bool = False
    ) -> Dict[str, Any]:
        """Free-simulation metrics: rmse, nll (mean per step), coverage_2sigma, steps, and
        diverged/divergence (whether and why the simulation runs away from the measured outputs,
        as `msgp eval` tests it; also warned as a RuntimeWarning); with filtered=True also
        "filtered", the same metrics of the one-step-ahead filtered predictions
        (`msgp eval --filtered`)."""
    def save(self, path: PathLike) -> None:
        """Writes the model file of `msgp fit` (JSON, atomically)."""
    @staticmethod
    def load(path: PathLike) -> "Msgp":
        """Reads a model file written by `msgp fit` or `save`."""
    def to_json(self) -> str: ...
    @staticmethod
    def from_json(text: str) -> "Msgp": ...
    @property
    def is_fitted(self) -> bool: ...
    @property
    def method(self) -> str: ...
    @property
    def history(self) -> Optional[Tuple[int, int]]:
        """The fitted model's (l_y, l_u); before a fit, as given (None for "auto")."""
    @property
    def inducing(self) -> Optional[int]: ...
    @property
    def iterations(self) -> Optional[int]: ...
    @property
    def seed(self) -> int: ...
    @property
    def likelihood(self) -> Optional[str]:
        """"free-run" or "filter" for MSGP; None for the other methods."""
    @property
    def warmup(self) -> int:
        """max(l_y, l_u): predictions start at this sample."""
    @property
    def input_names(self) -> List[str]: ...
    @property
    def output_names(self) -> List[str]: ...
    @property
    def params(self) -> Dict[str, Union[Array, float]]:
        """pseudo_inputs, pseudo_targets, log_lengthscales, log_signal_var,
        log_process_noise, log_obs_noise, linear_mean (zero unless fitted with
        settings={"mean": "linear"}), u_mean, u_std, y_mean, y_std (arrays) and
        noise_floor (float); names and units as in the model file."""
    @property
    def training(self) -> Dict[str, Any]: ...
    @property
    def report(self) -> Optional[Dict[str, Any]]: ...
    @property
    def diverged(self) -> Optional[str]:
        """Why the fitted model's free simulation over its training inputs diverges (the fit
        also warns with a RuntimeWarning), or None."""
        ...
    @property
    def reference(self) -> Optional[Dict[str, Array]]: ...

def load(
    files: Union[PathLike, Sequence[PathLike]],
    *,
    inputs: Optional[Sequence[str]] = None,
    outputs: Optional[Sequence[str]] = None,
    topic: Optional[str] = None,
    sort_time: bool = False,
) -> Dict[str, Any]:
    """CSV data files read as `msgp fit --data` reads them: {"inputs", "outputs", "parts",
    "warnings"}, each part {"source", "episode", "t", "u", "y"} (u, y: T × d arrays); warnings
    are lines about the data that do not stop the load (an irregular time step, rows sorted).
    Bad data raise InvalidInputError naming the file, line and column; `sort_time` sorts each
    trajectory's rows by time instead of refusing rows out of order (`msgp fit --sort-time`)."""

def synthetic_system(k: int, seed: int = 0, noise: str = "std") -> Dict[str, Any]:
    """Synthetic system k (1–5) of the paper's Table 2: u_train, y_train, u_test, y_test
    (1-D arrays) and history (l_y, l_u)."""

def defaults(
    what: str, *, method: Optional[str] = None, likelihood: Optional[str] = None
) -> Dict[str, Any]:
    """Defaults of "pendulum", "stability", "learn", "learner" or "fit" settings ("learner":
    the loop on a plant, `learn_policy(env=...)`'s, as the named Pendulum-v1 task sets it); for
    "learn" and "fit",
    those of the model `method` ("msgp" when None; a "linear-kf" loop warm-starts and searches
    over 10 s; a method's fit settings are the shared ones and its own); for "learn" with
    method "msgp", `likelihood` ("free-run" or "filter") picks that loop's defaults (the
    filtered loop starts every fit from the linear-kf model)."""

def run_episode(
    controller: Optional[Gains] = None,
    *,
    seconds: float = 10.0,
    seed: int = 0,
    theta0: Optional[float] = None,
    excitation_rms: float = 1.0,
    params: Optional[Dict[str, Any]] = None,
) -> Dict[str, Any]:
    """One seeded pendulum episode (as `msgp sim pendulum`): arrays t, command, meas_theta,
    meas_x, latent_*, u (n, 1), y (n, 2) and the dict info. controller: "hand-tuned"
    (default), "apollo-lqr", "zero", "random", a dict of gains or 5 gains."""

def stability_test(
    gains: Gains,
    *,
    seed: int = 0,
    params: Optional[Dict[str, Any]] = None,
    criteria: Optional[Dict[str, Any]] = None,
) -> Dict[str, Any]:
    """The stability test (as `msgp sim stability`): passed, gains, seed, starts."""

def learn_policy(
    method: str = "msgp",
    iterations: int = 8,
    seed: int = 0,
    *,
    likelihood: Optional[str] = None,
    params: Optional[Dict[str, Any]] = None,
    settings: Optional[PendulumLearnSettings] = None,
    progress: Optional[Callable[[Dict[str, Any]], Any]] = None,
) -> List[Dict[str, Any]]:
    """PILCO with MSGP, GP-NARX or linear-kf models on the simulated pendulum; one report per
    iteration; `likelihood` ("free-run" or "filter", MSGP only) picks the MSGP fits' training
    objective and that loop's defaults (`defaults("learn", likelihood=...)`). Releases the GIL;
    takes minutes with the defaults. `progress` is called with
    each iteration's report as it completes; Ctrl-C or an exception it raises stops the loop
    within one model fit and raises."""

class Policy:
    """A learned policy: `policy(obs)` gives the command for an observation (inside the command
    bounds), remembering what a stateful policy needs between calls until `reset()`; `save`
    writes the versioned policy file, `Policy.load` reads one."""

    def __call__(self, observation: ArrayLike) -> Array: ...
    def reset(self) -> None: ...
    @property
    def kind(self) -> str:
        """The policy's family: "pid", "linear" or "rbf"."""
    def to_dict(self) -> Dict[str, Any]: ...
    def save(self, path: PathLike) -> None: ...
    @staticmethod
    def load(path: PathLike) -> "Policy": ...

def learn_on_plant(
    plant: Any,
    spec: Dict[str, Any],
    task: Dict[str, Any],
    *,
    settings: Optional[LearnerSettings] = None,
    method: str = "msgp",
    likelihood: Optional[str] = None,
    seed: int = 0,
    progress: Optional[Callable[[Dict[str, Any]], Any]] = None,
) -> Dict[str, Any]:
    """The PILCO loop on `plant` (an object with `reset(seed) -> obs` and
    `step(command) -> (obs, terminated, truncated)`), its signals described by `spec`, the
    task in the target form; `method` ("msgp", "gp-narx", "linear-kf") and, for "msgp",
    `likelihood` ("filter" or "free-run") choose the loop's model, derived from `settings`;
    `msgp.learn_policy(env=...)` builds on it. Returns {"iterations", "episodes",
    "policy", "settings"}; an exception of the plant or of `progress`, or Ctrl-C, is raised as
    it was with the run so far in its `partial` attribute."""

def table1_plan(
    seeds: Sequence[int],
    *,
    data_dir: Optional[PathLike] = None,
    only: Optional[Sequence[str]] = None,
    methods: Optional[Sequence[str]] = None,
    likelihoods: Optional[Sequence[str]] = None,
    inducing: int = 100,
    iters: Optional[int] = None,
    optimizer: str = "adam",
    history: str = "paper",
) -> Dict[str, Any]:
    """The validated plan of a Table 1 reproduction (as `msgp reproduce table1` takes its
    options): {"plan", "units", "section"}; each unit is one benchmark × seed × column, in the
    serial run's order. `history`: "paper" (Table 3's) or "auto" (chosen on each fit's
    training part, as `msgp fit --history auto`). Used by `msgp.sweep`."""

def table1_unit(plan: Dict[str, Any], unit: Dict[str, Any]) -> Dict[str, Any]:
    """Fits one unit of a plan and returns its cell (metrics of the moment-matching and the
    mean-feedback simulation, train seconds, iterations). Releases the GIL."""

def table1_report(
    plan: Dict[str, Any],
    results: Sequence[Tuple[Dict[str, Any], Dict[str, Any]]],
    command: str,
    seconds: float,
    machine: Optional[str] = None,
) -> Dict[str, Any]:
    """{"section", "markdown", "rows"} of a finished plan from its (unit, cell) pairs in any
    order: the section `msgp reproduce table1` writes and the rows of its --json."""

def figure4_plan(
    seeds: Sequence[int],
    *,
    tier: str = "apollo",
    params: Optional[Dict[str, Any]] = None,
    models: Optional[Sequence[str]] = None,
    iterations: int = 8,
    budget: Optional[Dict[str, Any]] = None,
    dir: Optional[PathLike] = None,
) -> Dict[str, Any]:
    """The validated plan of a Figure 4 reproduction (as `msgp reproduce figure4` takes its
    options): {"plan", "units", "pending", "section", "dir"}; each unit is one model × seed, in
    the serial run's order; `pending` lacks a finished run in the plan's folder. Used by
    `msgp.sweep`."""

def figure4_budget() -> Dict[str, Any]:
    """The budget options of `msgp learn-policy` / `msgp reproduce figure4` at their defaults
    (None: the model's own default)."""

def figure4_unit(plan: Dict[str, Any], unit: Dict[str, Any], dir: PathLike) -> Dict[str, Any]:
    """Runs one learning run of a plan, writes its folder into `dir` (summary.json last) and
    returns its summary. Takes minutes; releases the GIL."""

def figure4_report(
    plan: Dict[str, Any],
    command: str,
    seconds: float,
    machine: Optional[str] = None,
) -> Dict[str, Any]:
    """{"section", "markdown", "plot"} of a plan whose every run is finished in its folder: the
    section `msgp reproduce figure4` writes and its cost-band plot (drawn)."""

def update_results_section(path: PathLike, name: str, body: str) -> None:
    """Replaces section `name` of the markdown file `path` (created when missing), atomically."""
