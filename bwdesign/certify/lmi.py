"""Linear matrix inequalities of the certificates, solved with cvxpy.

This is the only module of bwdesign that imports cvxpy (docs/design.md, section
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
  Clarabel only: :mod:`.synthesis` falls back on an exact pole search, which is
  faster and more reliable than SCS on those programs). Only ``OPTIMAL`` is accepted;
  ``OPTIMAL_INACCURATE`` is reported as unverified. Solver exceptions are caught
  and turned into a status string; they never escape as a traceback.
- The programs are built once per thread with cvxpy parameters (DPP), so a
  bisection re-solves without recompiling.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import threading
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np

from .. import interrupts

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

#: Solvers tried in this order; the first ``OPTIMAL`` answer is used.
SOLVERS: tuple[str, ...] = ("CLARABEL", "SCS")

_OPTIONS: dict[str, dict[str, Any]] = {
    "CLARABEL": {},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 50_000},
}

_E3 = np.array([[0.0], [0.0], [1.0]])
_I3 = np.eye(3)


@dataclass(frozen=True)
class LMISolution:
    """Outcome of one semidefinite program.

    Attributes
    ----------
    ok : bool
        True only when a solver returned ``OPTIMAL``.
    status : str
        ``"optimal"``, another cvxpy status (``"optimal_inaccurate"`` is
        unverified), or ``"solver_error"``.
    solver : str
        The solver whose answer is reported (``""`` when none ran).
    objective : float or None
        Optimal value (the margin ``t``, or ``tau`` for the least-norm program).
    values : Mapping[str, ndarray]
        Read-only values of the named variables (empty unless ``ok``).
    attempts : tuple of str
        One line per solver tried, e.g. ``"CLARABEL: optimal_inaccurate"``.
    """

    ok: bool
    status: str
    solver: str
    objective: float | None
    values: Mapping[str, np.ndarray] = field(default_factory=dict)
    attempts: tuple[str, ...] = ()

    def __getitem__(self, name: str) -> np.ndarray:
        return self.values[name]


#: Solvers that print errors even when not verbose (SCS, through ``sys.stdout``
#: and its C library); their output is discarded so that ``--json`` stays clean.
_NOISY = frozenset({"SCS"})


def _flush_c_stdio() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except Exception:  # noqa: BLE001 - no C runtime to flush (non-POSIX builds)
        pass


@contextlib.contextmanager
def _quiet_c_output(active: bool) -> Iterator[None]:
    """Silence a solver's writes to stdout/stderr (``sys.stdout`` and descriptors 1, 2)."""
    if not active:
        yield
        return
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
    except (OSError, ValueError, AttributeError):  # no real descriptors (embedded use)
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    sink = io.StringIO()  # SCS's Python binding prints through sys.stdout
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            yield
    finally:
        _flush_c_stdio()  # what the library buffered goes to /dev/null, not to the caller
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


def solver_versions() -> dict[str, str]:
    """Versions of cvxpy and of the solvers used, for reproducibility blocks."""
    out = {"cvxpy": cp.__version__}
    for mod in ("clarabel", "scs"):
        try:
            out[mod] = __import__(mod).__version__
        except Exception:  # noqa: BLE001 - a missing solver is reported, not raised
            out[mod] = "unavailable"
    return out


#: Status SCS returns when it caught a SIGINT itself (``SCS_SIGINT`` in scs.h);
#: cvxpy reports it as a solver error.
_SCS_SIGINT = -5


def _solve_once(problem: cp.Problem, solver: str, opts: dict[str, Any]) -> None:
    """``problem.solve(solver=solver, warm_start=False, **opts)``, but a Ctrl-C always cancels.

    The three public steps of :meth:`cvxpy.Problem.solve` (compile, solve,
    unpack), so that the solver's raw answer can be read: SCS installs its own
    SIGINT handler while it runs and answers a Ctrl-C with a status cvxpy calls
    a solver error, which the fall-back logic would take for a failed solve.
    A SIGINT during a Clarabel solve reaches Python when the solve returns.
    """
    # warm_start=False: a reused (cached) program must give the same answer as a
    # fresh one, so reports are reproducible bit for bit.
    data, chain, inverse = problem.get_problem_data(solver, solver_opts=opts)
    raw = chain.solve_via_data(problem, data, warm_start=False, verbose=False, solver_opts=opts)
    info = raw.get("info") if isinstance(raw, dict) else None
    if isinstance(info, dict) and info.get("status_val") == _SCS_SIGINT:
        interrupts.interrupt()
    interrupts.check()  # one the handler recorded while a library held it
    problem.unpack_results(raw, chain, inverse)


def solve(
    problem: cp.Problem,
    variables: Mapping[str, cp.Variable],
    *,
    first_only: bool = False,
    options: Mapping[str, Any] | None = None,
) -> LMISolution:
    """Solve with Clarabel, fall back to SCS, accept only ``OPTIMAL``.

    Parameters
    ----------
    problem : cvxpy.Problem
    variables : mapping of str to cvxpy.Variable
        Variables whose values are returned.
    first_only : bool
        Try only the first solver (synthesis: its exact pole search is a better
        fall-back than a slow SCS run on an ill-conditioned program).
    options : mapping, optional
        Extra options of the first solver (merged over the defaults).

    Returns
    -------
    LMISolution
        Never raises on solver trouble: a failure is a status.
    """
    attempts: list[str] = []
    last_status = "solver_error"
    last_solver = ""
    for i, solver in enumerate(SOLVERS[:1] if first_only else SOLVERS):
        opts = _OPTIONS[solver] | (dict(options or {}) if i == 0 else {})
        try:
            with warnings.catch_warnings(), _quiet_c_output(solver in _NOISY):
                warnings.simplefilter("ignore")
                _solve_once(problem, solver, opts)
        except cp.error.SolverError as err:
            attempts.append(f"{solver}: solver error: {' '.join(str(err).split())[:200]}")
            last_status, last_solver = "solver_error", solver
            continue
        except Exception as err:  # noqa: BLE001 - any solver crash is a status, not a traceback
            attempts.append(f"{solver}: {type(err).__name__}: {' '.join(str(err).split())[:200]}")
            last_status, last_solver = "solver_error", solver
            continue
        status = str(problem.status)
        attempts.append(f"{solver}: {status}")
        last_status, last_solver = status, solver
        if status == cp.OPTIMAL:
            values = {}
            finite = True
            for name, var in variables.items():
                if var.value is None:
                    finite = False
                    break
                arr = np.array(var.value, dtype=float)
                if not np.all(np.isfinite(arr)):
                    finite = False
                    break
                arr.setflags(write=False)
                values[name] = arr
            if not finite:
                attempts[-1] += " (non-finite values)"
                last_status = "solver_error"
                continue
            return LMISolution(
                ok=True,
                status=status,
                solver=solver,
                objective=float(problem.value),
                values=values,
                attempts=tuple(attempts),
            )
    return LMISolution(
        ok=False,
        status=last_status,
        solver=last_solver,
        objective=None,
        attempts=tuple(attempts),
    )


# -- parametrised programs, built once per thread -----------------------------

_LOCAL = threading.local()


@dataclass
class _Program:
    problem: cp.Problem
    params: dict[str, cp.Parameter]
    variables: dict[str, cp.Variable]


def _program(key: str, build: Callable[[], _Program]) -> _Program:
    cache = getattr(_LOCAL, "programs", None)
    if cache is None:
        cache = _LOCAL.programs = {}
    prog = cache.get(key)
    if prog is None:
        prog = cache[key] = build()
    return prog


def _sym(X: cp.Expression) -> cp.Expression:
    return (X + X.T) / 2


def _run(prog: _Program, values: Mapping[str, Any], *, first_only: bool = False) -> LMISolution:
    for name, value in values.items():
        prog.params[name].value = value
    return solve(prog.problem, prog.variables, first_only=first_only)


def _build_lipschitz() -> _Program:
    A = cp.Parameter((3, 3), name="A")
    L2 = cp.Parameter(nonneg=True, name="L2")
    mu = cp.Parameter(nonneg=True, name="mu")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    top = A.T @ P + P @ A + 2 * mu * P + L2 * (_E3 @ _E3.T)
    Pe3 = P @ _E3
    M = cp.bmat([[top, Pe3], [Pe3.T, -np.ones((1, 1))]])
    cons = [_sym(M) << -t * np.eye(4), P >> t * _I3]
    prob = cp.Problem(cp.Maximize(t), cons)
    return _Program(prob, {"A": A, "L2": L2, "mu": mu}, {"P": P, "t": t})


def lipschitz_margin(A: np.ndarray, *, L: float, mu: float = 0.0) -> LMISolution:
    """S-procedure (bounded-real) LMI for ``|phi| <= L |eps3|``.

    Maximises ``t`` subject to
    ``[[A'P + PA + 2 mu P + L^2 e3 e3', P e3], [e3' P, -1]] <= -t I`` and
    ``P >= t I``.

    Parameters
    ----------
    A : ndarray, shape (3, 3)
        Scaled error-dynamics matrix.
    L : float
        Scaled Lipschitz constant (>= 0).
    mu : float
        Scaled decay rate (>= 0).
    """
    prog = _program("lipschitz", _build_lipschitz)
    return _run(prog, {"A": np.asarray(A, float), "L2": float(L) ** 2, "mu": float(mu)})


def _build_sector() -> _Program:
    A = cp.Parameter((3, 3), name="A")
    k = [cp.Parameter(name=f"k{i}") for i in range(2)]
    mu = cp.Parameter(nonneg=True, name="mu")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    PE = P @ (_E3 @ _E3.T)
    cons = [P >> t * _I3, P << _I3]
    for ki in k:
        M = A.T @ P + P @ A - ki * (PE + PE.T) + 2 * mu * P
        cons.append(_sym(M) << -t * _I3)
    prob = cp.Problem(cp.Maximize(t), cons)
    return _Program(prob, {"A": A, "k0": k[0], "k1": k[1], "mu": mu}, {"P": P, "t": t})


def sector_margin(A: np.ndarray, *, k_lo: float, k_hi: float, mu: float = 0.0) -> LMISolution:
    """Common quadratic Lyapunov function for ``A - k e3 e3'`` at both sector ends.

    Maximises ``t`` subject to ``He(P (A - k e3 e3' + mu I)) <= -t I`` for
    ``k in {k_lo, k_hi}``, ``t I <= P <= I``. The LMI is affine in ``k``, so it
    then holds on the whole interval.
    """
    prog = _program("sector", _build_sector)
    return _run(
        prog,
        {"A": np.asarray(A, float), "k0": float(k_lo), "k1": float(k_hi), "mu": float(mu)},
    )


def _build_sampled() -> _Program:
    Ad = [cp.Parameter((3, 3), name=f"Ad{i}") for i in range(2)]
    r2 = cp.Parameter(nonneg=True, name="r2")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    cons = [P >> t * _I3, P << _I3]
    for A in Ad:
        PA = P @ A
        M = cp.bmat([[r2 * P, PA.T], [PA, P]])
        cons.append(_sym(M) >> t * np.eye(6))
    prob = cp.Problem(cp.Maximize(t), cons)
    return _Program(prob, {"Ad0": Ad[0], "Ad1": Ad[1], "r2": r2}, {"P": P, "t": t})


def sampled_margin(Ad_lo: np.ndarray, Ad_hi: np.ndarray, *, r: float) -> LMISolution:
    """Discrete polytopic LMI ``A_i' P A_i <= r^2 P`` at both vertices (Schur form).

    Maximises ``t`` subject to ``[[r^2 P, A_i' P], [P A_i, P]] >= t I`` for both
    vertices and ``t I <= P <= I``.
    """
    prog = _program("sampled", _build_sampled)
    return _run(
        prog,
        {"Ad0": np.asarray(Ad_lo, float), "Ad1": np.asarray(Ad_hi, float), "r2": float(r) ** 2},
    )


def _build_sampled_delta() -> _Program:
    D = [cp.Parameter((3, 3), name=f"D{i}") for i in range(2)]
    sh = cp.Parameter(nonneg=True, name="sh")
    c = cp.Parameter(nonneg=True, name="c")
    P = cp.Variable((3, 3), symmetric=True, name="P")
    t = cp.Variable(name="t")
    cons = [P >> t * _I3, P << _I3]
    for Di in D:
        PD = P @ Di
        M = cp.bmat([[PD + PD.T + c * P, sh * PD.T], [sh * PD, -P]])
        cons.append(_sym(M) << -t * np.eye(6))
    prob = cp.Problem(cp.Maximize(t), cons)
    return _Program(prob, {"D0": D[0], "D1": D[1], "sh": sh, "c": c}, {"P": P, "t": t})


def sampled_delta_margin(D_lo: np.ndarray, D_hi: np.ndarray, *, h: float, c: float) -> LMISolution:
    """The sampled LMI in delta form, well conditioned for small sample times.

    With ``A_d = I + h D`` (scaled time), ``A_d' P A_d - r^2 P < 0`` divided by
    ``h`` is ``He(P D) + c P + h D' P D < 0`` (``c = (1 - r^2)/h``); its Schur
    complement form ``[[He(P D) + c P, sqrt(h) D' P], [sqrt(h) P D, -P]] <= -t I``
    is solved at both vertices with ``t I <= P <= I``, maximising ``t``.

    Parameters
    ----------
    D_lo, D_hi : ndarray, shape (3, 3)
        Scaled delta-form matrices at the two ends.
    h : float
        Scaled sample time (``sqrt(a1) dt``).
    c : float
        Scaled ``(1 - r^2)/dt``.
    """
    prog = _program("sampled_delta", _build_sampled_delta)
    return _run(
        prog,
        {
            "D0": np.asarray(D_lo, float),
            "D1": np.asarray(D_hi, float),
            "sh": float(np.sqrt(h)),
            "c": float(c),
        },
    )


_SYM_INDEX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _build_least_norm() -> _Program:
    B = [cp.Parameter((3, 3), symmetric=True, name=f"B{i}{j}") for i, j in _SYM_INDEX]
    Q = cp.Variable((3, 3), symmetric=True, name="Q")
    tau = cp.Variable(name="tau")
    P = sum(Q[i, j] * Bk for (i, j), Bk in zip(_SYM_INDEX, B, strict=True))
    cons = [Q >> _I3, _sym(P) << tau * _I3]
    prob = cp.Problem(cp.Minimize(tau), cons)
    params = {f"B{i}{j}": Bk for (i, j), Bk in zip(_SYM_INDEX, B, strict=True)}
    return _Program(prob, params, {"Q": Q, "tau": tau})


def least_norm_lyapunov(basis: Mapping[tuple[int, int], np.ndarray]) -> LMISolution:
    """Least ``tau`` with ``A'P + PA <= -I`` and ``P <= tau I``, parametrised by ``Q``.

    The Lyapunov operator is a bijection, so ``{P : A'P + PA <= -I}`` is
    ``{P(Q) : Q >= I}`` with ``P(Q)`` the solution of ``A'P + PA = -Q``. The
    program is written in ``Q`` (which is well conditioned even when ``P`` is
    not) with ``P(Q) = sum_ij Q_ij B_ij``.

    Parameters
    ----------
    basis : mapping of (i, j) to ndarray, shape (3, 3)
        ``B_ij`` for ``(i, j)`` in ``(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)``:
        the solution of ``A'P + PA = -E_ij`` where ``E_ij`` has ones at
        ``(i, j)`` and ``(j, i)``; for ``i != j`` pass the solution for that
        symmetric pair (``Q_ij`` multiplies it once). Normalise it so that its
        norms are of order one.
    """
    prog = _program("least_norm", _build_least_norm)
    values = {}
    for i, j in _SYM_INDEX:
        Bk = np.asarray(basis[(i, j)], float)
        values[f"B{i}{j}"] = (Bk + Bk.T) / 2
    return _run(prog, values)


#: Weight of ``||P||_F^2`` next to ``||Y||^2`` in the refinement objective.
REFINE_P_WEIGHT = 1e-2


def _objective(
    t: cp.Variable, P: cp.Variable, Y: cp.Variable, params: dict[str, cp.Parameter], refine: bool
) -> tuple[Any, list[Any]]:
    """Maximise the margin, or (refine) keep ``t >= t_min`` and minimise the gains.

    The refinement objective ``||Y||^2 + w ||P||_F^2`` is strictly convex, so the
    refined design is unique (the max-margin face is not) and reproducible.
    """
    if not refine:
        return cp.Maximize(t), []
    t_min = cp.Parameter(nonneg=True, name="t_min")
    params["t_min"] = t_min
    obj = cp.Minimize(cp.sum_squares(Y) + REFINE_P_WEIGHT * cp.sum_squares(P))
    return obj, [t >= t_min]


def _build_sector_synthesis(with_disk: bool, refine: bool = False) -> Callable[[], _Program]:
    def build() -> _Program:
        A0 = cp.Parameter((3, 3), name="A0")
        C = cp.Parameter((1, 3), name="C")
        k = [cp.Parameter(name=f"k{i}") for i in range(2)]
        mu = cp.Parameter(nonneg=True, name="mu")
        params = {"A0": A0, "C": C, "k0": k[0], "k1": k[1], "mu": mu}
        P = cp.Variable((3, 3), symmetric=True, name="P")
        Y = cp.Variable((3, 1), name="Y")
        t = cp.Variable(name="t")
        PA = P @ A0 - Y @ C  # P (A0 - l C) with Y = P l
        PE = P @ (_E3 @ _E3.T)
        cons = [P >> t * _I3, P << _I3]
        for ki in k:
            M = PA + PA.T - ki * (PE + PE.T) + 2 * mu * P
            cons.append(_sym(M) << -t * _I3)
        if with_disk:
            R = cp.Parameter(nonneg=True, name="R")
            params["R"] = R
            D = cp.bmat([[-R * P, PA], [PA.T, -R * P]])
            cons.append(_sym(D) << -t * np.eye(6))
        obj, extra = _objective(t, P, Y, params, refine)
        prob = cp.Problem(obj, cons + extra)
        return _Program(prob, params, {"P": P, "Y": Y, "t": t})

    return build


def sector_synthesis(
    A0: np.ndarray,
    C: np.ndarray,
    *,
    k_lo: float,
    k_hi: float,
    mu: float = 0.0,
    radius: float | None = None,
    t_min: float | None = None,
) -> LMISolution:
    """Gains ``l = P^-1 Y`` making the sector LMI hold, with an optional pole disk.

    Maximises ``t`` subject to ``He(P A0 - Y C - k P e3 e3' + mu P) <= -t I`` at
    both sector ends, ``t I <= P <= I`` and, when ``radius`` is given,
    ``[[-R P, P A], [A' P, -R P]] <= -t I`` (eigenvalues of ``A = A0 - l C`` in
    the disk ``|s| < R``). With ``t_min`` it instead keeps ``t >= t_min`` and
    minimises ``||Y||^2 + w ||P||_F^2`` (the refinement stage: the smallest
    gains with that margin, a unique point).
    """
    refine = t_min is not None
    key = f"sector_synthesis_disk{radius is not None}_refine{refine}"
    prog = _program(key, _build_sector_synthesis(radius is not None, refine))
    values: dict[str, Any] = {
        "A0": np.asarray(A0, float),
        "C": np.asarray(C, float).reshape(1, 3),
        "k0": float(k_lo),
        "k1": float(k_hi),
        "mu": float(mu),
    }
    if radius is not None:
        values["R"] = float(radius)
    if refine:
        values["t_min"] = float(t_min)
    return _run(prog, values, first_only=True)


def _build_sampled_synthesis(with_disk: bool, refine: bool = False) -> Callable[[], _Program]:
    def build() -> _Program:
        FR = [cp.Parameter((3, 3), name=f"FR{i}") for i in range(2)]
        HR = [cp.Parameter((1, 3), name=f"HR{i}") for i in range(2)]
        r2 = cp.Parameter(nonneg=True, name="r2")
        params = {"FR0": FR[0], "FR1": FR[1], "HR0": HR[0], "HR1": HR[1], "r2": r2}
        P = cp.Variable((3, 3), symmetric=True, name="P")
        Y = cp.Variable((3, 1), name="Y")
        t = cp.Variable(name="t")
        cons = [P >> t * _I3, P << _I3]
        for F_i, H_i in zip(FR, HR, strict=True):
            PA = P @ F_i - Y @ H_i  # P (I - K C) F R(rho) with Y = P K
            M = cp.bmat([[r2 * P, PA.T], [PA, P]])
            cons.append(_sym(M) >> t * np.eye(6))
        if with_disk:
            F = cp.Parameter((3, 3), name="F")
            H = cp.Parameter((1, 3), name="H")
            c = cp.Parameter(name="c")
            rho = cp.Parameter(nonneg=True, name="rho")
            params.update({"F": F, "H": H, "c": c, "rho": rho})
            PM = P @ F - Y @ H - c * P
            D = cp.bmat([[rho * P, PM.T], [PM, rho * P]])
            cons.append(_sym(D) >> t * np.eye(6))
        obj, extra = _objective(t, P, Y, params, refine)
        prob = cp.Problem(obj, cons + extra)
        return _Program(prob, params, {"P": P, "Y": Y, "t": t})

    return build


def sampled_synthesis(
    F: np.ndarray,
    H: np.ndarray,
    *,
    rho_lo: float,
    rho_hi: float,
    r: float,
    disk: tuple[float, float] | None = None,
    t_min: float | None = None,
) -> LMISolution:
    """Discrete gains ``K = P^-1 Y`` for ``eps+ = (I - K C) F diag(1, 1, rho) eps``.

    Maximises ``t`` subject to ``[[r^2 P, A_i' P], [P A_i, P]] >= t I`` at
    ``rho in {rho_lo, rho_hi}`` with ``P A_i = (P F - Y H) diag(1, 1, rho_i)``,
    ``t I <= P <= I`` and, when ``disk = (c, radius)`` is given, the nominal
    poles ``eig(F - K H)`` in the disk ``|z - c| < radius``. With ``t_min``:
    the refinement stage, as in :func:`sector_synthesis`.

    Parameters
    ----------
    F : ndarray, shape (3, 3)
        Scaled one-sample transition of the model copy.
    H : ndarray, shape (1, 3)
        Scaled ``C F`` (the measurement seen through one sample).
    """
    F = np.asarray(F, float)
    H = np.asarray(H, float).reshape(1, 3)
    refine = t_min is not None
    key = f"sampled_synthesis_disk{disk is not None}_refine{refine}"
    prog = _program(key, _build_sampled_synthesis(disk is not None, refine))
    values: dict[str, Any] = {"r2": float(r) ** 2}
    for i, rho in enumerate((rho_lo, rho_hi)):
        R = np.diag([1.0, 1.0, float(rho)])
        values[f"FR{i}"] = F @ R
        values[f"HR{i}"] = H @ R
    if disk is not None:
        values.update({"F": F, "H": H, "c": float(disk[0]), "rho": float(disk[1])})
    if refine:
        values["t_min"] = float(t_min)
    return _run(prog, values, first_only=True)


# -- the disturbance observer's lumped error (bwdesign.certify.disturbance) ----------


def _lumped_problem(
    A_o: np.ndarray, vertices: list[np.ndarray], *, discrete: bool
) -> tuple[cp.Problem, dict[str, cp.Variable]]:
    """``P = blockdiag(P_o, p)`` with a margin ``t`` on the observable block and the vertices.

    Continuous: ``He(P_o A_o) <= -t I`` and ``He(P A_i) <= -t I``; discrete (Schur
    form): ``A_o' P_o A_o <= P_o - t I`` and ``A_i' P A_i <= P - t I``; ``t <= p``,
    ``t I <= P_o <= I``, ``p <= 1``.
    """
    Po = cp.Variable((3, 3), symmetric=True, name="Po")
    p = cp.Variable(name="p")
    t = cp.Variable(name="t")
    P = cp.bmat([[Po, np.zeros((3, 1))], [np.zeros((1, 3)), cp.reshape(p, (1, 1), order="C")]])
    cons = [Po >> t * _I3, Po << _I3, p >= t, p <= 1]

    def neg(Pm, A, n):
        if discrete:
            PA = Pm @ A
            M = cp.bmat([[Pm - t * np.eye(n), PA.T], [PA, Pm]])
            return _sym(M) >> 0
        PA = Pm @ A
        return _sym(PA + PA.T) << -t * np.eye(n)

    if A_o is not None:
        cons.append(neg(Po, np.asarray(A_o, float), 3))
    for A in vertices:
        cons.append(neg(P, np.asarray(A, float), 4))
    return cp.Problem(cp.Maximize(t), cons), {"Po": Po, "p": p, "t": t}


def lumped_margin(
    A_o: np.ndarray | None, vertices: list[np.ndarray], *, discrete: bool
) -> LMISolution:
    """A block-diagonal Lyapunov function for the disturbance observer's error.

    In the coordinates ``(e1, e2, ew, eta)`` (scaled) the error matrix at the
    degenerate vertex (hysteresis not contracting: sector ``k = 0`` or jump slope
    ``rho = 1``) is ``blockdiag(A_o, 0)`` (continuous) or ``blockdiag(A_o, 1)``
    (discrete): only its observable block ``A_o`` is constrained there. The other
    vertices ``A_i`` (4x4) are constrained in full. Maximises the margin ``t``
    (see the module conventions); ``A_o = None`` when no vertex is degenerate.
    """
    prob, variables = _lumped_problem(A_o, list(vertices), discrete=discrete)
    return solve(prob, variables)


def lumped_sampled_synthesis(
    F: np.ndarray, h: np.ndarray, J: np.ndarray | None, *, r: float
) -> LMISolution:
    """Discrete gains for the disturbance observer's observable part (``l3 = 0`` split).

    Variables ``P_o`` (3x3), ``p``, ``Y = P_o K_o`` and the margin ``t``; with
    ``P_o Phi_o = P_o F - Y h'`` (``h' = C F``) every block is affine in them:

    - nominal decay (``rho = 1``): ``[[r^2 P_o - t I, (P_o Phi_o)'], [P_o Phi_o, P_o]] >= 0``;
    - the contracting vertex ``A_d = blockdiag(Phi_o, 1) J``:
      ``[[P - t I, (blockdiag(P_o Phi_o, p) J)'], [blockdiag(P_o Phi_o, p) J, P]] >= 0``
      (``J = None``: no such vertex);
    - ``t I <= P_o <= I``, ``t <= p <= 1``. Maximises ``t``; ``K_o = P_o^-1 Y``.
    """
    F = np.asarray(F, float)
    h = np.asarray(h, float).reshape(1, 3)
    Po = cp.Variable((3, 3), symmetric=True, name="Po")
    p = cp.Variable(name="p")
    Y = cp.Variable((3, 1), name="Y")
    t = cp.Variable(name="t")
    PoPhi = Po @ F - Y @ h
    cons = [Po >> t * _I3, Po << _I3, p >= t, p <= 1]
    M = cp.bmat([[float(r) ** 2 * Po - t * _I3, PoPhi.T], [PoPhi, Po]])
    cons.append(_sym(M) >> 0)
    if J is not None:
        z31 = np.zeros((3, 1))
        pp = cp.reshape(p, (1, 1), order="C")
        P = cp.bmat([[Po, z31], [z31.T, pp]])
        PA = cp.bmat([[PoPhi, z31], [z31.T, pp]]) @ np.asarray(J, float)
        M4 = cp.bmat([[P - t * np.eye(4), PA.T], [PA, P]])
        cons.append(_sym(M4) >> 0)
    prob = cp.Problem(cp.Maximize(t), cons)
    return solve(prob, {"Po": Po, "p": p, "Y": Y, "t": t})


# -- robust invariant ellipsoid (bwdesign.certify.robust) ----------------------


def robust_ellipsoid(
    As: list[np.ndarray], Bs: list[np.ndarray], c: np.ndarray, *, a: float, eps: float = 1e-5
) -> LMISolution:
    """Smallest peak of ``c'z`` over a common invariant ellipsoid of ``z+ = A_i z + B_i w``.

    The ellipsoid is ``{z' Q^-1 z <= 1}``. For every ``i``:
    ``[[a Q, 0, Q A_i'], [0, (1-a) diag(lam), B_i'], [A_i Q, B_i, Q]] >= eps I``
    (the congruence by ``diag(Q, I, Q)`` of the Schur form of
    ``V(z+) <= a V(z) + (1-a) sum lam_j w_j^2``, ``V = z'Q^-1 z``), ``sum(lam) <= 1``
    (inputs normalised to ``|w_j| <= 1``) and ``Q >= eps I``; minimises ``c'Qc``, the
    squared peak of ``c'z`` on the ellipsoid. Variables ``Q`` (n x n), ``lam`` (m,).
    """
    n = As[0].shape[0]
    m = Bs[0].shape[1]
    Q = cp.Variable((n, n), symmetric=True)
    lam = cp.Variable(m, nonneg=True)
    cons = [Q >> eps * np.eye(n), cp.sum(lam) <= 1.0]
    cc = np.asarray(c, dtype=float).reshape(n)
    for A, B in zip(As, Bs, strict=True):
        M = cp.bmat(
            [
                [a * Q, np.zeros((n, m)), Q @ A.T],
                [np.zeros((m, n)), (1 - a) * cp.diag(lam), B.T],
                [A @ Q, B, Q],
            ]
        )
        cons.append(_sym(M) >> eps * np.eye(2 * n + m))
    prob = cp.Problem(cp.Minimize(cc @ Q @ cc), cons)
    opts = {"chordal_decomposition_enable": False}
    return solve(prob, {"Q": Q, "lam": lam}, first_only=True, options=opts)


def robust_observer_synthesis(
    F: np.ndarray,
    Bw: np.ndarray,
    c: np.ndarray,
    *,
    rho: tuple[float, float],
    a: float,
    noise: float,
    disk: tuple[float, float] | None = None,
    eps: float = 1e-7,
) -> LMISolution:
    """Gain ``K = P^-1 Y`` minimising the peak of ``c'e``, ``e+ = (I - K C)(F D_i e + Bw w) + K n``.

    ``C = e1'``, ``D_i = diag(1, 1, rho_i)``, ``V = e'Pe``, inputs normalised (``n`` by
    ``noise``). With ``Y = P K``, ``G = P - Y C``: ``[[a P, 0, (G F D_i)'], [0, (1-a)
    diag(lam), (PB)'], [G F D_i, PB, P]] >= eps I`` with ``PB = [G Bw, noise Y]``,
    ``sum(lam) <= 1``, ``P >= eps I``, optionally the nominal poles in the disk ``disk =
    (centre, r)`` (``[[r P, M'], [M, r P]] >= eps I``, ``M = G F - centre P``); minimises
    ``g >= c'P^-1 c`` (Schur), the squared peak of ``c'e`` on ``{e'Pe <= 1}``. Clarabel runs
    without chordal decomposition (with it, these programs failed often).
    """
    F, Bw, cc = np.asarray(F, float), np.asarray(Bw, float), np.asarray(c, float).reshape(3, 1)
    m = Bw.shape[1] + int(noise > 0)
    P, Y = cp.Variable((3, 3), symmetric=True), cp.Variable((3, 1))
    lam, g = cp.Variable(m, nonneg=True), cp.Variable()
    G = P - Y @ np.array([[1.0, 0.0, 0.0]])
    PB = G @ Bw if noise <= 0 else cp.hstack([G @ Bw, float(noise) * Y])
    epi = cp.bmat([[cp.reshape(g, (1, 1), order="C"), cc.T], [cc, P]])
    cons = [P >> eps * _I3, cp.sum(lam) <= 1.0, _sym(epi) >> 0]
    for r in rho:
        PA = G @ F @ np.diag([1.0, 1.0, float(r)])
        Z = np.zeros((3, m))
        M = cp.bmat([[a * P, Z, PA.T], [Z.T, (1 - a) * cp.diag(lam), PB.T], [PA, PB, P]])
        cons.append(_sym(M) >> eps * np.eye(6 + m))
    if disk is not None:
        PM = G @ F - disk[0] * P
        cons.append(_sym(cp.bmat([[disk[1] * P, PM.T], [PM, disk[1] * P]])) >> eps * np.eye(6))
    variables = {"P": P, "Y": Y, "lam": lam, "g": g}
    opts = {"chordal_decomposition_enable": False}
    return solve(cp.Problem(cp.Minimize(g), cons), variables, first_only=True, options=opts)


def _disk(X: Any, XA: Any, r: float | None, t: Any = 0.0) -> list[Any]:
    """``[[-r X, X A], [A' X, -r X]] <= -t I``: the eigenvalues of ``A`` in ``|s| < r``."""
    return [] if r is None else [_sym(cp.bmat([[-r * X, XA], [XA.T, -r * X]])) << -t * np.eye(6)]


def theorem1_synthesis(
    Ahat: np.ndarray, *, mu: float, lmax: float, radius: float | None = None
) -> LMISolution:
    """Gains for Theorem 1 (sign corrected) in scaled coordinates: least ``||X||``.

    ``He(X Ahat - Z e1') + 2 mu X <= -I``, ``p/100 I <= X <= p I``, ``||Z|| <= lmax p``
    (so the scaled gain ``||X^-1 Z|| <= 100 lmax``), and with ``radius`` the poles of
    ``Ahat - X^-1 Z e1'`` in ``|s| <= radius`` (:func:`_disk`); minimises ``p`` (then
    ``l = X^-1 Z``). Variables ``X`` (3 x 3), ``Z`` (3,), ``p``.
    """
    X = cp.Variable((3, 3), symmetric=True)
    Z = cp.Variable((3, 1))
    p = cp.Variable()
    C = np.array([[1.0, 0.0, 0.0]])
    XA = X @ Ahat - Z @ C
    He = XA + XA.T + 2 * mu * X
    cons = [X >> (p / 100.0) * _I3, X << p * _I3, _sym(He) << -_I3, cp.norm(Z) <= lmax * p]
    cons += _disk(X, XA, radius)
    return solve(cp.Problem(cp.Minimize(p), cons), {"X": X, "Z": Z, "p": p})


def lipschitz_synthesis(
    Ahat: np.ndarray, *, L: float, mu: float, lmax: float, radius: float | None = None
) -> LMISolution:
    """Feasibility of the lipschitz S-procedure LMI in ``(X, Z = X l)`` (scaled coordinates).

    ``[[He(X Ahat - Z e1') + 2 mu X + L^2 e3 e3' + t I, X e3], [e3' X, -1 + t]] <= 0``,
    ``I <= X <= p I``, ``||Z|| <= lmax p``, with ``radius`` the pole disk with margin
    ``t`` (:func:`_disk`); maximises the margin ``t`` (certified when ``t > 0``).
    """
    X = cp.Variable((3, 3), symmetric=True)
    Z = cp.Variable((3, 1))
    t = cp.Variable()
    C = np.array([[1.0, 0.0, 0.0]])
    XA = X @ Ahat - Z @ C
    He = XA + XA.T + 2 * mu * X + L**2 * (_E3 @ _E3.T)
    M = cp.bmat([[He + t * _I3, X @ _E3], [_E3.T @ X, cp.reshape(t - 1, (1, 1), order="C")]])
    p = cp.Variable()
    cons = [X >> _I3, X << p * _I3, cp.norm(Z) <= lmax * p, _sym(M) << 0, t <= 1.0]
    cons += _disk(X, XA, radius, t)
    return solve(cp.Problem(cp.Maximize(t), cons), {"X": X, "Z": Z, "t": t})
