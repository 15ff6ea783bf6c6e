"""
The hysteresis observer in a filterpy loop
==========================================

The observers follow filterpy's interface: ``predict(u)`` propagates the model copy
over one sample with the input held, ``update(z)`` corrects it with the measured
displacement (``update(None)`` for a missing sample), and ``filterpy.common.Saver``
records every attribute after each step. Here the hysteresis observer (PHSO) runs on
a record of the ``paper_experiment`` stage with 20 nm sensor noise and a dropped
sample, started from a wrong state, and recovers the hysteresis state ``x3`` that is
never measured.
"""

import matplotlib.pyplot as plt
import numpy as np
from filterpy.common import Saver

from bwdesign import HysteresisObserver, load_plant, simulate_zoh

plant = load_plant("paper_experiment")
dt = 2e-4
t = np.arange(0.0, 1.0, dt)
u = 70 + 40 * np.sin(2 * np.pi * 2 * t)  # V, held over each sample
X = simulate_zoh(plant, u, dt, x0=np.zeros(3))  # row k+1: the state after u[k] was held
rng = np.random.default_rng(0)
z = X[1:, 0] + 0.02 * rng.standard_normal(len(u))  # measured x1 (um)

# %%
# The filtering loop, as any filterpy filter runs it
# ---------------------------------------------------
obs = HysteresisObserver(plant, (8, 64, -512), dt=dt)
obs.x = np.array([5.0, 0.0, 0.0])  # a wrong start: 5 um off, no hysteresis estimate
saver = Saver(obs)
for k in range(len(u)):
    obs.predict(u[k])
    obs.update(None if k == 2000 else z[k])  # sample 2000 is missing
    saver.save()
saver.to_array()
xhat = np.asarray(saver.x)
print(f"{obs!r}")
print(f"final |x3 - x3hat| = {abs(X[-1, 2] - xhat[-1, 2]):.3g} um")

# %%
# ``batch_filter`` runs the same loop in one call
xb = HysteresisObserver(plant, (8, 64, -512), dt=dt).batch_filter(z, u)
print(f"batch_filter: shape {xb.shape}")

fig, (a1, a2) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
a1.plot(t, X[1:, 0], label="x1 (true)")
a1.plot(t, xhat[:, 0], "--", label="x1 estimate")
a1.set_ylabel("x1 (um)")
a1.legend()
a2.plot(t, X[1:, 2], label="x3 (true, never measured)")
a2.plot(t, xhat[:, 2], "--", label="x3 estimate")
a2.set_xlabel("t (s)")
a2.set_ylabel("x3 (um)")
a2.legend()
fig.tight_layout()
