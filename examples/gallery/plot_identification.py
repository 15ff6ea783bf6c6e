"""
Identification from a bench record
==================================

``identify`` fits the model to a record ``(t, u, y)`` by output error on the exact ZOH
model, with no initial guess, and states what the record determines: 95 % intervals on
every parameter (a parameter the record cannot pin down is reported as not
determined), the fit on held-out validation records and an ``[uncertainty]`` box for
the robust certificates. The records here are the repository's examples
(``examples/identification/``: the ``paper_experiment`` stage, 10 nm noise, a 3 um
sensor offset; 1 s of training and 0.5 s of validation at 5 kHz).
"""

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from bwdesign import identify, load_plant, simulate_zoh
from bwdesign.identify import load_data

# this script's folder (sphinx-gallery runs it there without defining __file__)
here = Path(__file__).resolve().parent if "__file__" in globals() else Path.cwd()
train = load_data(here.parent / "identification" / "train.csv")
valid = load_data(here.parent / "identification" / "valid.csv")
res = identify(train, validation=valid, seed=0)
print(res.reason)
true = load_plant("paper_experiment")
for name in ("a1", "a2", "a3", "alpha", "beta", "gamma"):
    est, (lo, hi) = getattr(res.params, name), res.ci95[name]
    print(f"{name:6s} {est:12.6g}  95 % [{lo:.6g}, {hi:.6g}]  true {getattr(true, name):.6g}")
fit = res.fit_percent
print(f"fit {fit['train']:.2f} % (training), {fit['validation']:.2f} % (validation)")
print(f"sensor offset {res.offset:.3f} um; converged: {res.converged}")

# %%
# The identified model beside the validation record
X = simulate_zoh(res.params, valid.u, valid.dt, x0=np.zeros(3))
fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5))
a1.plot(valid.t, valid.y, label="measured y")
a1.plot(valid.t, X[1:, 0] + res.offset, "--", label="identified model")
a1.set_xlabel("t (s)")
a1.set_ylabel("y (um)")
a1.legend()
a2.plot(valid.u, valid.y, lw=0.8)
a2.set_xlabel("u (V)")
a2.set_ylabel("y (um)")
a2.set_title("the validation record's hysteresis loops")
fig.tight_layout()
