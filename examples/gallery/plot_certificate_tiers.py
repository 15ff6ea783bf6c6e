"""
Certificate tiers against the input-rate envelope
=================================================

The certificates bound the hysteresis error through the input rate ``|u'|``: each
tier holds up to an envelope, and below it states a decay rate. ``certify`` answers
for one envelope; each tier's ``max_udot`` is the largest envelope it certifies. Here
the paper's experimental gains (8, 64, -512) on ``paper_experiment``: the corrected
Theorem 1 certifies no real trajectory, the Lipschitz tier a slow one, and the sector
and sampled tiers (which use the sign of the hysteresis error) about ten times the
envelope the paper's 1 Hz sine needs.
"""

import matplotlib.pyplot as plt
import numpy as np

from bwdesign import Sine, certify, derive_envelope, load_plant

p = load_plant("paper_experiment")
gains, dt = (8, 64, -512), 2e-4
env = derive_envelope(p, Sine(amplitude=80, offset=100, frequency=1))
rep = certify(p, gains, udot_max=env.udot_max, dt=dt)
print(f"envelope of the 1 Hz sine: {env.udot_max:.1f} V/s; strongest tier: {rep.best}")
for c in rep.certificates:
    print(f"  {c.name:10s} holds={c.holds!s:5s} max |u'| = {c.max_udot:.4g} V/s")

# %%
# The decay rate each tier certifies, as the envelope grows
rates = np.geomspace(10, 6000, 9)
decay = {c.name: [] for c in rep.certificates}
for v in rates:
    for c in certify(p, gains, udot_max=v, dt=dt).certificates:
        decay[c.name].append(c.decay_rate if c.holds else np.nan)

fig, ax = plt.subplots(figsize=(7, 4))
for name, d in decay.items():
    ax.semilogx(rates, d, "o-", label=name)
ax.axvline(env.udot_max, color="k", ls=":", label="the 1 Hz sine's envelope")
ax.set_xlabel("input-rate envelope |u'| (V/s)")
ax.set_ylabel("certified decay rate (1/s)")
ax.legend()
fig.tight_layout()
