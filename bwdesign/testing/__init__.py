"""Testing helpers for a user's CI: assertions, the ``[requirements]`` checks and a pytest plugin.

``bwdesign check FILE.toml...`` runs the same checks from the command line;
``pytest --bwdesign-configs 'configs/*.toml'`` (the plugin in :mod:`.plugin`)
makes one test item per stage file and requirement.
"""

from .asserts import (
    assert_c_matches_python,
    assert_certified,
    assert_synthesis_feasible,
    assert_tracks,
)
from .checks import Check, check_requirements, failure_table

__all__ = [
    "assert_certified",
    "assert_synthesis_feasible",
    "assert_tracks",
    "assert_c_matches_python",
    "Check",
    "check_requirements",
    "failure_table",
]
