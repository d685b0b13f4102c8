"""Long calls release the GIL: Python threads keep running while Rust fits."""

import random
import threading
import time

import msgp


def busy_fraction(work):
    """Runs `work()` while another Python thread counts; returns (seconds, fraction), the
    fraction being the counts during `work` over what the thread counts alone in that time."""
    counts = {"n": 0}
    stop = threading.Event()

    def count():
        while not stop.is_set():
            counts["n"] += 1

    counter = threading.Thread(target=count)
    counter.start()
    try:
        time.sleep(0.3)
        n0, t0 = counts["n"], time.perf_counter()
        time.sleep(0.3)
        rate = (counts["n"] - n0) / (time.perf_counter() - t0)  # alone (main thread asleep)
        n0, t0 = counts["n"], time.perf_counter()
        work()
        seconds = time.perf_counter() - t0
        during = counts["n"] - n0
    finally:
        stop.set()
        counter.join()
    return seconds, during / (rate * seconds)


def test_fit_releases_the_gil():
    data = msgp.synthetic_system(4, seed=0)
    # 100 Adam steps on the exact GP's likelihood (n × n factorisations): a fit long enough to
    # measure (L-BFGS, the default, converges in ~0.2 s; the default bound is O(n m²), ~0.1 s)
    model = msgp.Msgp(history=data["history"], method="gp-narx", inducing=50, iterations=100,
                      seed=0, settings={"solver": "adam", "objective": "exact"})
    seconds, fraction = busy_fraction(lambda: model.fit(data["u_train"], data["y_train"]))
    print(f"fit took {seconds:.2f} s; the other thread ran at {fraction:.0%} of its solo rate meanwhile")
    assert model.is_fitted and seconds > 0.2
    # a call that holds the GIL lets the thread run only until the first switch (~5 ms)
    assert fraction > 0.1


def test_the_gil_check_catches_a_call_that_holds_it():
    """Control: `sorted` of a long list holds the GIL throughout; the same check fails it."""
    xs = [random.random() for _ in range(2_000_000)]
    seconds, fraction = busy_fraction(lambda: sorted(xs))
    print(f"sorted took {seconds:.2f} s; the other thread ran at {fraction:.1%} of its solo rate")
    assert fraction < 0.1


def test_fits_in_threads_agree():
    """Two threads fitting the same data get bit-identical models."""
    data = msgp.synthetic_system(3, seed=1)
    models = [msgp.Msgp(history=(1, 1), method="gp-narx", inducing=20, iterations=30) for _ in range(2)]
    threads = [threading.Thread(target=m.fit, args=(data["u_train"], data["y_train"])) for m in models]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert models[0].is_fitted and models[1].is_fitted
    a, b = (m.to_json() for m in models)
    strip = lambda s: [line for line in s.splitlines() if "train_seconds" not in line]  # noqa: E731
    assert strip(a) == strip(b)


def test_one_model_shared_between_threads():
    """Predicting from one thread while another refits the same object works (no borrow
    errors): each call sees the old or the new model."""
    data = msgp.synthetic_system(3, seed=2)
    model = msgp.Msgp(history=(1, 1), method="gp-narx", inducing=20, iterations=20)
    model.fit(data["u_train"], data["y_train"])
    errors = []

    def refit():
        try:
            for _ in range(3):
                model.fit(data["u_train"], data["y_train"])
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    worker = threading.Thread(target=refit)
    worker.start()
    scores = []
    while worker.is_alive():
        scores.append(model.score(data["u_test"], data["y_test"])["rmse"])
    worker.join()
    assert not errors, errors
    assert scores and len(set(scores)) == 1  # every refit gives the identical model
