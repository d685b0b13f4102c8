"""msgp: Gaussian-process dynamics models optimised for long-term predictions (MSGP).

A numpy-native front of the Rust library (Doerr et al., "Optimizing Long-term Predictions for
Model-based Policy Search", CoRL 2017)::

    import msgp
    data = msgp.synthetic_system(4, seed=0)
    model = msgp.Msgp(history=data["history"], seed=0).fit(data["u_train"], data["y_train"])
    mean, var = model.simulate(data["u_test"], data["y_test"])
    print(model.score(data["u_test"], data["y_test"]))
    model.save("sys4.model.json")  # the model file of `msgp fit`

Every number is computed in Rust; long calls release the GIL. Errors derive from
``MsgpError``; bad input raises ``InvalidInputError``, which is also a ``ValueError``.
"""

from . import _msgp
from . import gym as _gym
from ._msgp import (
    InvalidInputError,
    ModelFileError,
    Msgp,
    MsgpError,
    NotFittedError,
    NumericalError,
    __version__,
    Policy,
    defaults,
    load,
    run_episode,
    stability_test,
    synthetic_system,
)


def learn_policy(
    method="msgp",
    iterations=None,
    seed=0,
    *,
    env=None,
    likelihood=None,
    params=None,
    settings=None,
    progress=None,
    **task,
):
    """PILCO on a plant. With ``env`` (a Gymnasium environment with a ``Box`` action space):
    the loop on that environment, returning a ``msgp.gym.LearnResult`` (``.policy``,
    ``.iterations``, ``.episodes``); ``task`` takes ``target``, ``widths``, ``episode_steps``,
    ``policy_horizon``, ``policy``, ``separate_starts``, ``width_scales``, ``angles`` and
    ``period`` (see ``msgp.gym``); ``method`` ("msgp", "gp-narx", "linear-kf") and, for
    "msgp", ``likelihood`` ("filter", the default, or "free-run") choose the loop's model.
    Without: the built-in simulated pendulum with the ``method``'s model ("msgp", "gp-narx",
    "pilco-narx", "linear-kf"; ``likelihood`` and ``params`` as for the pendulum), returning
    one report per iteration (8 by default)."""
    if env is not None:
        if params is not None:
            raise InvalidInputError(
                "learn_policy(env=...): params belong to the built-in pendulum; the "
                "environment's loop takes its model settings in settings=..."
            )
        return _gym.learn_policy(
            env,
            seed=seed,
            iterations=iterations,
            settings=settings,
            method=method,
            likelihood=likelihood,
            progress=progress,
            **task,
        )
    if task:
        raise InvalidInputError(
            f"{', '.join(sorted(task))}: options of learn_policy(env=...), not of the built-in "
            "pendulum"
        )
    return _msgp.learn_policy(
        method,
        8 if iterations is None else iterations,
        seed,
        likelihood=likelihood,
        params=params,
        settings=settings,
        progress=progress,
    )


def __getattr__(name):
    # ``msgp.sweep`` is imported on first use: imported here eagerly, ``python -m msgp.sweep``
    # would find it in sys.modules before running it as the main module (a runpy warning)
    if name == "sweep":
        import importlib  # noqa: PLC0415

        return importlib.import_module(".sweep", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "InvalidInputError",
    "ModelFileError",
    "Msgp",
    "MsgpError",
    "NotFittedError",
    "NumericalError",
    "Policy",
    "__version__",
    "defaults",
    "learn_policy",
    "load",
    "run_episode",
    "stability_test",
    "sweep",
    "synthetic_system",
]
