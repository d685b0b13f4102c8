"""Can the arm-mounted pendulum be swung up, and how much rail does it take?

A cross-entropy search over open-loop acceleration commands (piecewise constant at 10 Hz) on the
pendulum's equations with the actuator's first-order lag (the pole of msgp_sim's default
parameters, hanging at the start): for each command limit it prints how far from upright the
best command ends, its angular and end-effector speed there, and the largest |x| on the way.
Behind docs/experiments/2026-12-06-angles-on-the-poles-tip-and-the-arm.md "Angles on the pole's tip, and the arm swing-up plant".

    python scripts/swing_up_feasibility.py            # about a minute
"""

import numpy as np

MASS, COM, LENGTH = 0.2903, 0.637, 1.067
INERTIA = MASS * LENGTH**2 / 12 + MASS * COM**2
DAMPING, GRAVITY, LAG = 0.0116, 9.81, 0.03


def simulate(commands, rate):
    """Final (θ, θ̇, x, ẋ) and max |x| of each row of commands, from hanging at π − 0.05."""
    n, steps = commands.shape
    dt = 2e-3
    sub = int(round(1 / rate / dt))
    th = np.full(n, np.pi - 0.05)
    w, x, v, acc, reach = (np.zeros(n) for _ in range(5))
    for k in range(steps):
        u = commands[:, k]
        for _ in range(sub):
            acc += (u - acc) * dt / LAG
            v += acc * dt
            x += v * dt
            wd = (MASS * COM * (GRAVITY * np.sin(th) - acc * np.cos(th)) - DAMPING * w) / INERTIA
            w += wd * dt
            th += w * dt
        reach = np.maximum(reach, np.abs(x))
    return th, w, x, v, reach


def search(limit, seconds, rate=10, seed=0, rounds=60, population=400, elite=40):
    rng = np.random.default_rng(seed)
    steps = int(seconds * rate)
    mean, std = np.zeros(steps), np.full(steps, float(limit))
    for _ in range(rounds):
        u = np.clip(mean + std * rng.standard_normal((population, steps)), -limit, limit)
        th, w, x, v, reach = simulate(u, rate)
        cost = 10 * (1 - np.cos(th)) + 0.05 * w**2 + 0.5 * v**2 + reach
        best = u[np.argsort(cost)[:elite]]
        mean, std = best.mean(0), best.std(0) + 1e-3
    th, w, x, v, reach = simulate(mean[None], rate)
    short = abs((th[0] + np.pi) % (2 * np.pi) - np.pi)
    return short, w[0], v[0], reach[0]


if __name__ == "__main__":
    for limit, seconds in [(3, 4.0), (5, 4.0), (8, 3.0), (10, 3.0), (15, 3.0)]:
        short, w, v, reach = search(limit, seconds)
        print(
            f"±{limit:>2} m/s², {seconds:.0f} s: {short:.2f} rad short of upright, "
            f"θ̇ {w:+.2f} rad/s, ẋ {v:+.2f} m/s, max |x| {reach:.2f} m"
        )
