"""Solving one semidefinite program: the solvers, their fall-back and the program cache.

The conventions of every program are in the package docstring (:mod:`bwdesign.certify.lmi`).
The names without a leading underscore that are not in ``__all__`` (:class:`Program`,
:func:`cached_program`, :func:`run_program`, :func:`sym`, ``E3``, ``I3``) are the shared
building blocks of :mod:`.analysis` and :mod:`.synthesis`, not API.
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

from ... import interrupts

__all__ = ["LMISolution", "SOLVERS", "solve", "solver_versions"]

#: Solvers tried in this order; the first ``OPTIMAL`` answer is used.
SOLVERS: tuple[str, ...] = ("CLARABEL", "SCS")

#: Clarabel on one thread: its thread pool does not survive a fork, and a forked child
#: (the report's second process) that solves after this process used the pool waits for
#: its threads forever; the small LMIs here gain nothing from threads (the answers are
#: the same: the stack's robust solve gave the same x to the bit, 1.04 s against 1.23 s).
_OPTIONS: dict[str, dict[str, Any]] = {
    "CLARABEL": {"max_threads": 1},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 50_000},
}

E3 = np.array([[0.0], [0.0], [1.0]])
I3 = np.eye(3)


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
class Program:
    """A cvxpy problem with its parameters and the variables it returns, built once per thread."""

    problem: cp.Problem
    params: dict[str, cp.Parameter]
    variables: dict[str, cp.Variable]


def cached_program(key: str, build: Callable[[], Program]) -> Program:
    """The program ``key`` of this thread, built by ``build()`` the first time."""
    cache = getattr(_LOCAL, "programs", None)
    if cache is None:
        cache = _LOCAL.programs = {}
    prog = cache.get(key)
    if prog is None:
        prog = cache[key] = build()
    return prog


def sym(X: cp.Expression) -> cp.Expression:
    """The symmetric part ``(X + X')/2`` (what cvxpy's ``>>`` needs)."""
    return (X + X.T) / 2


def run_program(
    prog: Program,
    values: Mapping[str, Any],
    *,
    first_only: bool = False,
    options: Mapping[str, Any] | None = None,
) -> LMISolution:
    """Set the parameters of ``prog`` to ``values`` and :func:`solve` it."""
    for name, value in values.items():
        prog.params[name].value = value
    return solve(prog.problem, prog.variables, first_only=first_only, options=options)
