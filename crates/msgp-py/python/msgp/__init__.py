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

from ._msgp import (
    InvalidInputError,
    ModelFileError,
    Msgp,
    MsgpError,
    NotFittedError,
    NumericalError,
    __version__,
    defaults,
    learn_policy,
    load,
    run_episode,
    stability_test,
    synthetic_system,
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
    "__version__",
    "defaults",
    "learn_policy",
    "load",
    "run_episode",
    "stability_test",
    "sweep",
    "synthetic_system",
]
