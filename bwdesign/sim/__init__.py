"""Closed-loop simulation: plant, observer and tracking controller.

Every simulation takes a :class:`bwdesign.ClosedLoop` (the model, the observer, the
law, dt, the delay, the start; built once, validated once, e.g.
:meth:`~bwdesign.ClosedLoop.from_config`) and what the run adds: the reference, the
duration, the true plant(s), the noise. Two paths:

- :func:`simulate`, the **sampled-data loop** a digital controller runs. The
  plant is the exact ZOH model (:mod:`bwdesign.model.plant`); observer and
  controller run at ``dt``. Per sample ``k``::

      z_k  = y(t_k) + n_k                      (seeded Gaussian noise, std in length units)
      observer.update(z_k)                     -> xhat_post(t_k)
      u_k  = controller(xhat_post, ref(t_k))   (clipped to u_limits)
      plant: hysteresis jump u_{k-1} -> u_k at t_k, then u_k held to t_{k+1}
      observer.predict(u_k)                    -> xhat_prior(t_{k+1})

  With ``delay=True`` (one-sample computation delay) the input computed at
  ``t_k`` is applied over ``[t_{k+1}, t_{k+2})``; the observer is always
  driven with the input the plant actually receives. With
  ``compensate_delay=True`` (default) the law uses the one-step prediction
  ``xhat_prior(t_{k+1})`` and ``ref(t_{k+1})``, as a careful implementation
  would; with ``False`` it uses the stale posterior.

- :func:`simulate_continuous`, the **continuous-time loop** of the paper's
  Section 4.2 (eq. 12 with the continuous observers eq. 3 / eq. 21), solved
  with a stiff method (``solve_ivp``, Radau by default, ``max_step``
  control). The PHSO needs ``u'`` while ``u`` itself depends on the
  estimate, whose x3 derivative depends on ``u'``: an implicit relation.
  It is solved *exactly*: with ``c = a1/a3`` (the law's weight on x3hat)
  and ``kappa(s, h) = alpha - beta s h - gamma |h|``::

      u' = A + c phi(u', x3hat) = A + c kappa(sign u', x3hat) u'
      =>  u' = A / (1 - c kappa(sign A, x3hat))

  where ``A`` collects every other term of ``d/dt`` eq. (12). The solution is
  unique when ``c kappa < 1`` on both branches (0.67 at most for the paper's
  simulation set, 0.63 for the experiment set); otherwise an error says the
  relation is ill-posed. This adds no dynamics, unlike an amplifier model,
  which would put an extra pole into a loop whose fast pole is at
  ``-lambda1 = -2.2e6`` rad/s and would have to be faster still to stay
  invisible. An amplifier state is available (``amplifier_bandwidth``, rad/s:
  ``u' = wc (u_cmd - u)``) for comparison. Jumps of ``u`` (triangle corners,
  steps: the law contains ``x_d'``) are applied as exact hysteresis jumps
  between integration segments.

Both return a :class:`SimulationResult`. A loop that diverges (non-finite or
huge states) is reported as ``stable = False`` with the record up to the
divergence; it never raises.

:func:`simulate_batch` runs the sampled-data loop for many true plants at once
(vectorised over scenarios; the Monte Carlo sweep's engine) and returns a
:class:`BatchResult`; :func:`simulate_corners` runs it at the corners of an
uncertainty box.
"""

from importlib import import_module
from typing import Any

#: Each public name and the module that defines it, imported on first use: importing
#: ``bwdesign.sim.compiled`` (the compiled kernels' process, :mod:`.kernel_process`) or
#: ``bwdesign.sim.kernel_process`` does not load scipy and the loop machinery.
_WHERE = {
    "BatchResult": ".batch",
    "simulate_batch": ".batch",
    "make_observer": ".closed_loop",
    "simulate": ".closed_loop",
    "ContinuousSolver": ".continuous",
    "simulate_continuous": ".continuous",
    "simulate_corners": ".corners",
    "Metrics": ".metrics",
    "steady_state_window": ".metrics",
    "tracking_metrics": ".metrics",
    "SimulationResult": ".result",
}


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(where, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


__all__ = [
    "Metrics",
    "tracking_metrics",
    "steady_state_window",
    "SimulationResult",
    "simulate",
    "simulate_batch",
    "simulate_corners",
    "BatchResult",
    "make_observer",
    "simulate_continuous",
    "ContinuousSolver",
]
