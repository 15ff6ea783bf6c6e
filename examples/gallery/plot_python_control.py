"""
The observer in a python-control interconnection
================================================

``as_iosystem()`` gives the continuous observer as a python-control
``NonlinearIOSystem`` with inputs ``u``, ``udot`` and ``y`` and outputs ``xhat[0..2]``,
named by python-control's vector convention, so ``control.interconnect`` connects it to
a plant whose output is named ``y``. The plant below is the Bouc-Wen model written as a
``NonlinearIOSystem`` in a few lines; the interconnection runs plant and observer
together and ``control.input_output_response`` simulates it.
"""

import control as ct
import matplotlib.pyplot as plt
import numpy as np

from bwdesign import HysteresisObserver, load_plant

p = load_plant("paper_experiment")


def plant_rhs(t, x, u, params):
    """The Bouc-Wen piezo model: inputs (u, udot), states (x1, x2, x3)."""
    v, vdot = u
    x1, x2, x3 = x
    return [
        x2,
        -p.a1 * x1 - p.a2 * x2 - p.a1 * x3 + p.a3 * v,
        p.alpha * vdot - p.beta * abs(vdot) * x3 - p.gamma * vdot * abs(x3),
    ]


plant = ct.nlsys(
    plant_rhs,
    lambda t, x, u, params: x[0],
    inputs=["u", "udot"],
    outputs="y",
    states=3,
    name="stage",
)
observer = HysteresisObserver(p, (8, 64, -512), dt=2e-4).as_iosystem(name="phso")
print(observer.name, observer.input_labels, observer.output_labels)

loop = ct.interconnect(
    [plant, observer],
    inplist=["u", "udot"],
    outlist=["y", "phso.xhat[0]", "phso.xhat[1]", "phso.xhat[2]"],
    outputs=["y", "x1hat", "x2hat", "x3hat"],
)

# %%
# A 2 Hz sine input (and its derivative, the hysteresis driver) for 0.5 s
t = np.linspace(0.0, 0.5, 2001)
w = 2 * np.pi * 2
U = np.vstack([70 + 40 * np.sin(w * t), 40 * w * np.cos(w * t)])
x0 = np.concatenate([np.zeros(3), [3.0, 0.0, 0.0]])  # the observer starts 3 um off
resp = ct.input_output_response(loop, t, U, x0, solve_ivp_method="LSODA")
y, x1hat, _, x3hat = resp.outputs
x3 = resp.states[2]
print(f"|x3 - x3hat| at the end: {abs(x3[-1] - x3hat[-1]):.3g} um")

fig, (a1, a2) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
a1.plot(t, y, label="y = x1")
a1.plot(t, x1hat, "--", label="observer x1")
a1.set_ylabel("um")
a1.legend()
a2.plot(t, x3, label="x3")
a2.plot(t, x3hat, "--", label="observer x3")
a2.set_xlabel("t (s)")
a2.set_ylabel("um")
a2.legend()
fig.tight_layout()
