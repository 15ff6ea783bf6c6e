#!/usr/bin/env bash
# CI of the firmware repository: the stage's requirements, then the helper tests.
set -euo pipefail
cd "$(dirname "$0")"
bwdesign check stage.toml --junit-xml requirements.xml
python -m pytest -q -p no:cacheprovider
