"""
Tracking with a mismatched plant
================================

The tracking loop is one object, ``ClosedLoop``: the model, the observer
(``ObserverSpec``), the law, the sample time, the computation delay and the start. The
digital tuning (``digital_tuning``) places the loop's poles for the sample rate and
checks the margins under mismatch and a one-sample delay. ``simulate_batch`` runs one
loop against many true plants at once. Here the PHSO and the disturbance observer PHDO
(an integrating disturbance state, for a model that is not exact) track the paper's
1 Hz sine on plants whose linear part is off by 5 % and hysteresis by 10 %.
"""

import matplotlib.pyplot as plt
import numpy as np

from bwdesign import (
    ClosedLoop,
    ObserverSpec,
    Sine,
    digital_tuning,
    load_plant,
    make_controller,
    simulate,
    simulate_batch,
)

p = load_plant("paper_experiment")
dt = 2e-4
ref = Sine(amplitude=80, offset=100, frequency=1)
tuning = digital_tuning(p, dt)
print(f"digital tuning: lambda = ({tuning.lambda1:g}, {tuning.lambda2:g})")
print(f"observer gains {np.round(tuning.gains, 2)}")
settings = tuning.controller_kwargs()  # gains, lambda1, lambda2, form, integral_rate
settings.pop("gains")
law = make_controller(p, dt=dt, **settings)

# %%
# The mismatched plants: linear part +-5 %, hysteresis +-10 %
plants = [
    p.replace(a1=1.05 * p.a1, a3=0.95 * p.a3),
    p.replace(a1=0.95 * p.a1, a3=1.05 * p.a3),
    p.replace(alpha=1.1 * p.alpha, beta=0.9 * p.beta),
    p.replace(alpha=0.9 * p.alpha, beta=1.1 * p.beta),
]
fig, ax = plt.subplots(figsize=(7, 4))
for kind in ("phso", "phdo"):
    loop = ClosedLoop(
        p, ObserverSpec.of(kind, tuning.gains), law, dt=dt, delay=True, start="reference"
    )
    b = simulate_batch(loop, ref, plants, duration=2.0)
    print(f"{kind}: max |e| per plant (um): {np.round(b.maxe, 4)}")
    r = simulate(loop, ref, duration=2.0, true_params=plants[0])
    ax.plot(r.t, r.e, label=f"{kind.upper()}, a1 +5 %, a3 -5 %")
ax.set_xlabel("t (s)")
ax.set_ylabel("tracking error x1 - x_d (um)")
ax.legend()
fig.tight_layout()

# %%
# With a1 high and a3 low the PHSO loop zig-zags at half the sample rate (its model's
# hysteresis absorbs the linear mismatch it cannot see); the PHDO's disturbance state
# takes the mismatch instead, and its error stays within a tenth of a micrometre on
# every plant above. The robust certificates (user guide, "Robust certificates over an
# uncertainty box") bound this over a whole box.
