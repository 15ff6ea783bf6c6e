"""
Synthesising certified observer gains
=====================================

``synthesize`` finds gains by an LMI for a requested envelope, decay rate and pole
radius, then certifies them from scratch (``SynthesisResult``: the continuous gains,
the discrete gains for firmware, the tier that holds and the envelope it reaches).
Below: gains for ``paper_experiment`` at 0.2 ms for three decay rates, and the error
poles of each design (``error_dynamics``).
"""

import matplotlib.pyplot as plt
import numpy as np

from bwdesign import error_dynamics, load_plant, synthesize

p = load_plant("paper_experiment")
dt, envelope = 2e-4, 400.0
fig, ax = plt.subplots(figsize=(6, 5))
for decay in (50.0, 100.0, 300.0):
    syn = synthesize(p, udot_max=envelope, decay=decay, dt=dt)
    print(f"decay {decay:g}: {syn.reason}")
    print(f"  gains {np.round(syn.gains, 2)}, discrete {np.round(syn.discrete_gains, 5)}")
    poles = np.asarray(error_dynamics(p, syn.gains, udot_max=envelope).poles)
    ax.plot(poles.real, poles.imag, "x", ms=10, mew=2, label=f"decay >= {decay:g} 1/s")
ax.axvline(0, color="k", lw=0.5)
ax.set_xlabel("Re (1/s)")
ax.set_ylabel("Im (rad/s)")
ax.set_title("observer error poles of the synthesised gains")
ax.legend()
fig.tight_layout()
