"""Typed exceptions (and the one warning category) raised by bwdesign.

Every exception subclasses a built-in (mostly :class:`ValueError`) so callers
can catch either the specific class or the built-in. Messages name the object,
what was expected and what was found. Every exception class of the package is
defined here; a module that raises one of its own kind (``SweepError`` in
:mod:`bwdesign.sim.sweep`, ``UsageError`` in :mod:`bwdesign.cli.args`,
``TuningWarning`` in :mod:`bwdesign.control.controllers`) re-exports it from here.
"""

from __future__ import annotations

__all__ = [
    "BWDesignError",
    "ConfigError",
    "ParameterError",
    "UnboundedModelError",
    "GainError",
    "InputError",
    "SolverError",
    "MissingExtraError",
    "NotCertifiedError",
    "OutputError",
    "SweepError",
    "UsageError",
    "RequirementFailed",
    "InternalError",
    "TuningWarning",
]


class BWDesignError(Exception):
    """Base class of every error bwdesign raises on purpose."""


class ParameterError(BWDesignError, ValueError):
    """A model parameter is missing, non-numeric, non-finite or out of range.

    Attributes
    ----------
    field : str or None
        Name of the offending parameter, when there is one.
    """

    def __init__(self, message: str, *, field: str | None = None):
        super().__init__(message)
        self.field = field


class ConfigError(BWDesignError, ValueError):
    """A configuration file or preset name cannot be used as given."""


class UnboundedModelError(BWDesignError, ValueError):
    """The Bouc-Wen parameters are outside the bounded class.

    Design and simulation functions refuse such a model unless they are called
    with ``allow_unbounded=True``.
    """


class GainError(BWDesignError, ValueError):
    """Observer or controller gains have the wrong shape, value or stability."""


class InputError(BWDesignError, ValueError):
    """A signal (input, measurement, time step) is malformed or non-finite."""


class SolverError(BWDesignError, RuntimeError):
    """A convex solver failed; the result is *not* a certificate."""


class MissingExtraError(BWDesignError, ImportError):
    """An optional dependency is not installed; the message names the extra to install.

    Subclasses :class:`ImportError` (what the failed import was), so code that
    guards an optional import with ``except ImportError`` keeps working.

    Attributes
    ----------
    extra : str
        The extra that installs it: ``pip install 'bwdesign[extra]'``.
    module : str
        The module that could not be imported.
    """

    def __init__(self, message: str, *, extra: str, module: str):
        super().__init__(message, name=module)
        self.extra = extra
        self.module = module


class NotCertifiedError(BWDesignError, RuntimeError):
    """A well-formed "no": nothing certifies what was asked for (exit 1 on the command line).

    Raised where going on would hand out an uncertified result, e.g. exporting
    firmware for gains that no certificate tier holds for.
    """


class OutputError(BWDesignError, ValueError):
    """An output path cannot be written safely (wrong kind, foreign files, no permission).

    Raised by :mod:`bwdesign.output.files` before any work is done when the
    target is refused, or at write time when the operating system refuses
    (disk full, permission); in both cases no user file was changed.
    """


class SweepError(BWDesignError, RuntimeError):
    """A sweep could not be completed (a chunk failed after its retries, no scheduler)."""


class UsageError(BWDesignError, ValueError):
    """Bad command-line input."""


class RequirementFailed(BWDesignError, AssertionError):
    """A requirement of a stage file does not hold (the pytest plugin's failed item)."""


class InternalError(RuntimeError):
    """bwdesign contradicts itself (a bug), e.g. a C template asks for a value nobody gives.

    Deliberately not a :class:`BWDesignError`: it is no user's mistake, so the
    command line shows its traceback instead of reporting bad input.
    """


class TuningWarning(UserWarning):
    """A tuning outside the paper's proof (e.g. ``lambda2 <= 3/2``) but not invalid."""
