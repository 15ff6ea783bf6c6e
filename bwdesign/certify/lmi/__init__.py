"""Linear matrix inequalities of the certificates, solved with cvxpy.

This is the only subpackage of bwdesign that imports cvxpy (docs/design.md, section
"Layers and data flow").
It knows nothing about Bouc-Wen models: every function takes *scaled* numpy
matrices (entries of order one, prepared by :mod:`bwdesign.certify`), solves
one small semidefinite program and returns an :class:`LMISolution`.

Conventions
-----------
- The certificate and synthesis programs maximise a margin ``t``: the LMIs
  are written ``M <= -t I`` (or ``>= t I``) together with ``P >= t I``. They are
  feasible for every input (``t`` may come out <= 0), so the answer to "does a
  certificate exist" is the sign of ``t``, never a solver's infeasibility flag.
  A positive ``t`` is still only a *candidate*: :mod:`bwdesign.certify`
  re-checks the returned matrices outside the solver before it calls anything
  certified. (Two programs minimise instead: the least-norm Lyapunov matrix of
  Theorem 1, and the synthesis refinement, which keeps half the best margin
  and minimises the gains so that the design is unique.)
- Homogeneous programs are normalised by ``P <= I``.
- Solvers: Clarabel first, SCS as fall-back (the synthesis programs use
  Clarabel only: :mod:`bwdesign.design.gains` falls back on an exact pole search, which is
  faster and more reliable than SCS on those programs). Only ``OPTIMAL`` is accepted;
  ``OPTIMAL_INACCURATE`` is reported as unverified. Solver exceptions are caught
  and turned into a status string; they never escape as a traceback.
- The programs are built once per thread with cvxpy parameters (DPP), so a
  bisection re-solves without recompiling.

Modules: :mod:`.core` (the solvers, :func:`solve`, the program cache), :mod:`.analysis`
(the certificate programs: margins, least-norm Lyapunov matrix, lumped error, robust
ellipsoid) and :mod:`.synthesis` (the gain syntheses). Their public names are re-exported
here; the solver settings (``SOLVERS``) live in :mod:`.core`, where :func:`solve` reads them.
"""

from __future__ import annotations

from .analysis import (
    least_norm_lyapunov,
    lipschitz_margin,
    lumped_margin,
    robust_ellipsoid,
    sampled_delta_margin,
    sampled_margin,
    sector_margin,
)
from .core import SOLVERS, LMISolution, solve, solver_versions
from .synthesis import (
    lipschitz_synthesis,
    lumped_sampled_synthesis,
    robust_observer_synthesis,
    sampled_synthesis,
    sector_synthesis,
    theorem1_synthesis,
)

__all__ = [
    "LMISolution",
    "SOLVERS",
    "solve",
    "lipschitz_margin",
    "sector_margin",
    "sampled_margin",
    "sampled_delta_margin",
    "least_norm_lyapunov",
    "sector_synthesis",
    "sampled_synthesis",
    "solver_versions",
    "lumped_margin",
    "lumped_sampled_synthesis",
    "robust_ellipsoid",
    "robust_observer_synthesis",
    "theorem1_synthesis",
    "lipschitz_synthesis",
]
