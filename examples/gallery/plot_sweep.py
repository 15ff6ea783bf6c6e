"""
A Monte Carlo sweep over an uncertainty box
===========================================

A sweep draws the true plant of every scenario from a box around the stage's
parameters (``UncertaintyBox``), seeds each scenario's sensor noise, and runs the
sampled loop for every observer with ``simulate_batch``: every scenario at once,
vectorised. ``run_sweep`` runs chunks in this process (``workers=0``, as here), on a
local Dask cluster (``workers=K``) or on a running scheduler
(``scheduler="tcp://host:8786"``); rows come back in scenario order, so the result does
not depend on where they ran. The command line is ``bwdesign sweep`` (the ``sweep``
extra: ``pip install 'bwdesign[sweep]'``). 48 scenarios keep this example short.
"""

import matplotlib.pyplot as plt
import numpy as np

from bwdesign import UncertaintyBox, load_config
from bwdesign.design import stage_tuning
from bwdesign.sim.sweep import draw_scenarios, run_sweep, spec_from_config

stage = load_config("paper_experiment")
box = UncertaintyBox.parse("a1=2%,a3=2%,alpha=10%,beta=10%,gamma=10%")
# the loop: the digital tuning at the stage's dt (the sweep simulates the gains it is given)
tuning = stage_tuning(stage, "digital")
spec = spec_from_config(
    stage,
    law=tuning,
    observers=("phso", "eso", "phdo"),
    noise_std=0.02,
    duration=1.0,
    delay=True,
    uncertainty=box,
)
scenarios = draw_scenarios(stage.plant, box, 48, seed=1)
rows = run_sweep(spec, scenarios, workers=0)
for kind in spec.observers:
    pick = rows["observer"] == kind
    maxe = rows["maxe"][pick]  # NaN for a run that diverged
    print(
        f"{kind}: MAXE median {np.nanmedian(maxe):.4g} um, worst {np.nanmax(maxe):.4g} um, "
        f"stable {rows['stable'][pick].mean():.0%}, "
        f"within the envelope {rows['within_envelope'][pick].mean():.0%}"
    )

# %%
fig, ax = plt.subplots(figsize=(7, 4))
for kind in spec.observers:
    pick = rows["observer"] == kind
    maxe = rows["maxe"][pick]
    ax.hist(np.log10(maxe[np.isfinite(maxe)]), bins=15, alpha=0.6, label=kind.upper())
ax.set_xlabel("log10 of the max tracking error over the window (um)")
ax.set_ylabel("scenarios")
ax.legend()
fig.tight_layout()
