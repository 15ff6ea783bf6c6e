"""Optional dependencies, grouped in the package's extras (``pip install 'bwdesign[NAME]'``).

The base install carries what the main job needs (numpy, scipy, control with
slycot, cvxpy, filterpy, matplotlib). A feature that needs more imports it
through :func:`require`, which raises :class:`~bwdesign.errors.MissingExtraError`
naming the extra to install instead of a bare :class:`ImportError`; the command
line turns that into one ``error:`` line and exit 2.
"""

from __future__ import annotations

from importlib import import_module
from types import ModuleType

from .errors import InputError, MissingExtraError

__all__ = ["EXTRAS", "require"]

#: Each extra with the modules it provides (pyproject.toml's optional-dependencies).
EXTRAS: dict[str, tuple[str, ...]] = {
    "sweep": ("dask", "distributed", "pyarrow", "tqdm"),
    "browser": ("selenium",),
    "docs": ("sphinx", "numpydoc", "sphinx_gallery", "myst_parser", "furo"),
}


def require(module: str, *, extra: str, feature: str) -> ModuleType:
    """Import an optional dependency, or say which extra installs it.

    Parameters
    ----------
    module : str
        Module to import (``"dask.distributed"``, ...).
    extra : str
        The extra that provides it, a key of :data:`EXTRAS`.
    feature : str
        What needs it, for the message (``"bwdesign sweep"``).

    Returns
    -------
    module
        The imported module.

    Raises
    ------
    MissingExtraError
        ``module`` (or a module it imports) is not installed.
    ValueError
        ``extra`` is not one of the package's extras (a programming error).

    Examples
    --------
    >>> require("bwdesign_no_such_module", extra="sweep", feature="a sweep")
    Traceback (most recent call last):
    ...
    bwdesign.errors.MissingExtraError: a sweep needs the optional dependency \
'bwdesign_no_such_module', which is not installed: pip install 'bwdesign[sweep]'
    """
    if extra not in EXTRAS:
        raise InputError(f"unknown extra {extra!r}; extras are {', '.join(sorted(EXTRAS))}")
    try:
        return import_module(module)
    except ModuleNotFoundError as err:
        missing = "" if err.name in (None, module) else f" (module {err.name!r} is missing)"
        raise MissingExtraError(
            f"{feature} needs the optional dependency {module!r}, which is not installed"
            f"{missing}: pip install 'bwdesign[{extra}]'",
            extra=extra,
            module=module,
        ) from err
