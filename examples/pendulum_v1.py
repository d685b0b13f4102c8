"""Gymnasium's Pendulum-v1 learned by msgp's preset, seed by seed, scored as the environment
scores it: the mean return of the final policy over 100 seeded random starts of 200 steps.

    python examples/pendulum_v1.py [--seeds 0 1 2 3 4] [--out results/pendulum-v1/runs.jsonl]

Each seed runs ``msgp.learn_policy(env=gym.make("Pendulum-v1"), seed=k)`` with nothing else
(1 random episode + 14 policy episodes of 100 steps: 75 s of interaction) and writes one JSON
row: the final score, the model each search ran on, each iteration's fit and search seconds
and the mean return of its 10 evaluation episodes (100 steps each; not training data). Any
keyword of ``learn_policy`` can be varied with ``--set key=json`` (e.g. ``--set
separate_starts=15``); the environment's constants with ``--env g=9.81 m=1.2 l=0.8``. ~3 min per seed on
two cores.
"""

import argparse
import json
import time

import gymnasium as gym
import numpy as np

import msgp

#: Seeds of the scoring starts: none of them is a training or evaluation episode's.
SCORE_SEED = 10_000


#: Constants of the environment set on ``env.unwrapped`` (``gym.make`` takes only ``g``).
ATTRIBUTES = ("m", "l", "max_torque", "max_speed", "dt")


def make(env_kwargs):
    """``Pendulum-v1`` with the given constants: ``g`` through ``gym.make``, mass, length and
    limits set on the environment itself (its ``step`` reads them)."""
    env = gym.make(
        "Pendulum-v1", **{k: v for k, v in env_kwargs.items() if k not in ATTRIBUTES}
    )
    for key in ATTRIBUTES:
        if key in env_kwargs:
            setattr(env.unwrapped, key, env_kwargs[key])
    return env


def score(policy, env_kwargs, starts=100, steps=200):
    """Mean return of ``policy`` over ``starts`` seeded episodes of ``steps`` steps."""
    env = make(env_kwargs)
    returns = []
    for k in range(starts):
        obs, _ = env.reset(seed=SCORE_SEED + k)
        total = 0.0
        for _ in range(steps):
            obs, reward, terminated, truncated, _ = env.step(
                np.asarray(policy(obs), dtype=np.float32)
            )
            total += reward
            if terminated or truncated:
                break
        returns.append(total)
    return float(np.mean(returns))


def run(seed, env_kwargs, overrides):
    clock = time.time()
    result = msgp.learn_policy(env=make(env_kwargs), seed=seed, **overrides)
    iterations = [
        {
            "iteration": r["iteration"],
            "search_model": r.get("search_model"),
            "linear_fit_failure": r.get("linear_fit_failure") is not None,
            "fit_seconds": round(r["fit_seconds"], 2),
            "search_seconds": round(r["search_seconds"], 2),
            "evaluation_return": round(r["evaluation_return"], 1),
        }
        for r in result.iterations
    ]
    return {
        "seed": seed,
        "env": env_kwargs,
        "overrides": overrides,
        "score": round(score(result.policy, env_kwargs), 1),
        "interaction_seconds": result.iterations[-1]["interaction_seconds"],
        "episodes": len(result.episodes),
        "wall_seconds": round(time.time() - clock),
        "iterations": iterations,
    }


def pairs(items):
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        out[key] = json.loads(value)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--out", default=None, help="append one JSON row per seed here")
    parser.add_argument("--set", nargs="*", default=[], help="learn_policy keyword=json")
    parser.add_argument("--env", nargs="*", default=[], help="Pendulum-v1 constant=json")
    args = parser.parse_args()
    overrides, env_kwargs = pairs(args.set), pairs(args.env)
    for seed in args.seeds:
        row = run(seed, env_kwargs, overrides)
        line = json.dumps(row)
        print(line, flush=True)
        if args.out:
            with open(args.out, "a") as f:
                f.write(line + "\n")


if __name__ == "__main__":
    main()
