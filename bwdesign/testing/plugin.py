"""pytest plugin: one test item per stage file and requirement (opt-in).

Enable it with ``pytest --bwdesign-configs 'configs/*.toml'`` or in the user's
``pyproject.toml``::

    [tool.bwdesign]
    configs = ["configs/*.toml"]

Each requirement of each file's ``[requirements]`` section becomes an item named
so that a failure reads as a sentence, e.g.
``configs/stage.toml::tracking ME <= 45 um``. Installed through the ``pytest11``
entry point; without either setting it does nothing.
"""

from __future__ import annotations

import glob
import tomllib
from pathlib import Path

import pytest

from ..errors import RequirementFailed

_SENTENCE = {
    "certified": "gains are certified",
    "min_decay": "certified decay >= {v:g} 1/s",
    "max_me_um": "tracking ME <= {v:g} um",
    "max_maxe_um": "tracking MAXE <= {v:g} um",
    "min_gain_margin_db": "gain margin >= {v:g} dB",
    "min_phase_margin_deg": "phase margin >= {v:g} deg",
    "baseline_stable": "the [baseline] controller's nominal loop is stable",
}
#: The true/false requirements (nothing to check when false).
_FLAGS = ("certified", "baseline_stable")


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("bwdesign", "bwdesign stage requirements")
    group.addoption(
        "--bwdesign-configs",
        action="append",
        default=[],
        metavar="GLOB",
        help="stage files whose [requirements] become test items (repeatable)",
    )


def _globs(config: pytest.Config) -> list[str]:
    globs = list(config.getoption("bwdesign_configs") or [])
    pyproject = Path(config.rootpath) / "pyproject.toml"
    if not globs and pyproject.is_file():
        try:  # utf-8-sig: as bwdesign reads stage files (a byte-order mark is accepted)
            text = pyproject.read_bytes().decode("utf-8-sig")
            table = tomllib.loads(text).get("tool", {}).get("bwdesign", {})
        except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError):
            table = {}
        found = table.get("configs", [])
        globs = [found] if isinstance(found, str) else list(found)
    return globs


def pytest_collection_modifyitems(
    session: pytest.Session, config: pytest.Config, items: list[pytest.Item]
) -> None:
    root = Path(config.rootpath)
    paths = sorted(
        {Path(p).resolve() for g in _globs(config) for p in glob.glob(str(root / g))}
        | {Path(p).resolve() for g in _globs(config) for p in glob.glob(g)}
    )
    for path in paths:
        items.extend(StageFile.from_parent(session, path=path).collect())


class StageFile(pytest.File):
    """The requirements of one stage file."""

    def collect(self):
        from ..errors import BWDesignError
        from ..model.config import load_config

        try:
            req = load_config(self.path).requirements
        except BWDesignError as err:
            yield RequirementItem.from_parent(
                self, name="is a valid stage file", key=None, error=str(err)
            )
            return
        if not req:
            yield RequirementItem.from_parent(
                self,
                name="has a [requirements] section",
                key=None,
                error="no [requirements] section",
            )
            return
        for key, value in req.items():
            if key in _SENTENCE and not (key in _FLAGS and value is False):
                yield RequirementItem.from_parent(
                    self,
                    name=_SENTENCE[key] if key in _FLAGS else _SENTENCE[key].format(v=value),
                    key=key,
                    error=None,
                )

    def checks(self):
        if not hasattr(self, "_checks"):
            from .checks import check_requirements

            self._checks = {c.name: c for c in check_requirements(self.path)}
        return self._checks


class RequirementItem(pytest.Item):
    def __init__(self, *, key: str | None, error: str | None, **kw) -> None:
        super().__init__(**kw)
        self.key = key
        self.error = error

    def runtest(self) -> None:
        from ..errors import BWDesignError

        if self.error is not None:
            raise RequirementFailed(self.error)
        try:
            check = self.parent.checks()[self.key]
        except BWDesignError as err:  # a stage the checks cannot run: a failed item, no traceback
            raise RequirementFailed(" ".join(str(err).split())) from None
        if not check.passed:
            raise RequirementFailed(check.text)

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, RequirementFailed):
            return f"{self.path.name}: {self.name}: {excinfo.value}"
        return super().repr_failure(excinfo, style=style)

    def reportinfo(self):
        return self.path, None, f"{self.path.name}: {self.name}"
