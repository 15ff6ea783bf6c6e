"""Certified robust observer bounds beside a brute-force simulation (the README's numbers).

Run with ``.venv/bin/python analysis/robust_observer_bounds.py`` (about a minute); it
prints one Markdown table on stdout and writes nothing.

For each case: :func:`bwdesign.certify_robust_observer` (16 seeded interior points) of
the given gains and :func:`bwdesign.synthesize_robust_observer`'s gains, beside the
worst posterior error of the sampled PHSO (model) run beside each true plant (every
corner of the box and 4 interior points), driven by seeded random inputs inside the
input range at up to the rate limit, the plant starting at rest at an equilibrium of
its first input and the observer on it.
"""

from __future__ import annotations

import numpy as np

from bwdesign import (
    BoxSampling,
    HysteresisObserver,
    UncertaintyBox,
    certify_robust_observer,
    load_config,
    preset,
    synthesize_robust_observer,
)
from bwdesign.model.plant import zoh_step

SEED = 7


def random_input(rng, n, lo, hi, udot, dt):
    """Piecewise-constant rates ``|u'| <= udot`` (30..100 %), reflected inside ``[lo, hi]``."""
    u = np.empty(n)
    u[0] = rng.uniform(lo, hi)
    k, rate = 0, 0.0
    for i in range(1, n):
        if i >= k:
            rate = rng.choice([-1.0, 1.0]) * udot * rng.uniform(0.3, 1.0)
            k = i + int(rng.integers(20, 400))
        v = u[i - 1] + rate * dt
        if not lo <= v <= hi:
            rate = -rate
            v = u[i - 1] + rate * dt
        u[i] = v
    return u


def worst_error(model, box, *, K, dt, udot, u_range, noise_max, seconds):
    """Max ``|x1hat - x1|``, ``|x3hat - x3|`` over the corners and 4 interior plants."""
    rng = np.random.default_rng(SEED)
    worst = np.zeros(3)
    for tp in box.vertices(model) + box.sample(model, rng, 4):
        n = int(seconds / dt)
        u = random_input(rng, n, *u_range, udot, dt)
        noise = rng.uniform(-noise_max, noise_max, n)
        x = np.array([tp.a3 * u[0] / tp.a1, 0.0, 0.0])
        obs = HysteresisObserver(model, dt=dt, discrete=K, x0=x.copy(), u_prev=u[0])
        u_prev = u[0]
        for k in range(n):
            x = zoh_step(tp, x, u_prev, u[k], dt)
            obs.predict(u[k])
            obs.update(x[0] + noise[k])
            worst = np.maximum(worst, np.abs(obs.x - x))
            u_prev = u[k]
    return worst[0], worst[2]


def cases():
    p = preset("paper_experiment")
    box = UncertaintyBox.from_dict(
        {k: {"rel": 0.02} for k in ("a1", "a2", "a3")}
        | {k: {"rel": 0.1} for k in ("alpha", "beta", "gamma")}
    )
    paper = (p, (786.2, 28982.94, -782.0931942250238), 2e-4, 80 * 2 * np.pi * 1.1, (0.0, 150.0))
    yield "paper_experiment", *paper, box, 0.0, 1.0
    yield "paper_experiment", *paper, box, 0.05, 1.0
    yield (
        "paper_experiment a3 +-60 %",
        *paper,
        UncertaintyBox.from_dict({"a3": {"rel": 0.6}}),
        0.0,
        1.0,
    )
    cfg = load_config("stack_actuator_800hz")
    stack = (cfg.plant, cfg.gains, cfg.dt, cfg.envelope().udot_max)
    yield "stack_actuator_800hz", *stack, (-20.0, 120.0), cfg.uncertainty, 0.01, 0.5


def main() -> None:
    print("| case | noise (um) | gains | certified x1, x3 (um) | simulated x1, x3 (um) | ratio |")
    print("|---|---|---|---|---|---|")
    for name, p, gains, dt, udot, rng, box, nm, sec in cases():
        kw = {"dt": dt, "uncertainty": box, "udot_max": udot, "input_range": rng}
        kw |= {"noise_max": nm, "sampling": BoxSampling(16)}
        runs = [("given", certify_robust_observer(p, gains, **kw))]
        if "60" not in name:
            for target in ("x3", "x1"):
                res = synthesize_robust_observer(p, target=target, **kw)
                runs.append((f"synthesised for {target}", res.certificate))
        for label, cert in runs:
            K = np.array(cert.details["K"])
            s1, s3 = worst_error(
                p, box, K=K, dt=dt, udot=udot, u_range=rng, noise_max=nm, seconds=sec
            )
            b1, b3 = cert.estimation_bound, cert.x3_estimation_bound
            print(
                f"| {name} | {nm:g} | {label} | {b1:.3g}, {b3:.3g} | {s1:.3g}, {s3:.3g} | "
                f"{b1 / s1:.2g}, {b3 / s3:.2g} |"
            )


if __name__ == "__main__":
    main()
