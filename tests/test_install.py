"""The package as a user gets it: extras, the built distributions, a fresh install.

The slow checks build the sdist and the wheel (``python -m build``: the wheel is
built from the sdist, so the sdist is complete), check them with ``twine check
--strict``, install the wheel with pip into a new virtual environment (not
editable, nothing of the source tree on ``sys.path``; dependencies from the
package index or pip's cache, pinned to this environment's versions so the
numbers are comparable) and, in an empty folder, run ``bwdesign init``,
``bwdesign report`` on the written config and on a preset, and the public API.
The installed package's ``certificate.json`` must equal the source tree's for
the same config: the whole document (it holds no date and no path, only the
config's file name and hash).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tarfile
import tomllib
import venv
import zipfile
from importlib import import_module
from importlib.metadata import distributions, version
from importlib.util import find_spec
from pathlib import Path

import pytest

import bwdesign
from bwdesign import MissingExtraError, load_config
from bwdesign.cli.init import starter_config
from bwdesign.extras import EXTRAS, require
from bwdesign.model.stage_presets import STAGES_DIR
from bwdesign.output.jsonenc import dump_json
from bwdesign.study import CERTIFICATE_PARTS, REPORT_SECTIONS, study

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
#: the six libraries, and numba for the batched loop's compiled step (bwdesign.sim.compiled:
#: the report's corner batches 10-15x faster, `make bench`)
BASE = {"numpy", "scipy", "control", "cvxpy", "filterpy", "matplotlib", "numba"}
#: the module (``bwdesign.cli.main`` the attribute is the function it defines)
main_mod = import_module("bwdesign.cli.main")
STAGE_FILES = sorted(p.name for p in STAGES_DIR.glob("*.toml"))


# -- extras (fast) ------------------------------------------------------------


def _modules(requirement: str) -> list[str]:
    """Import names a requirement provides: ``dask[distributed]>=1`` -> dask, distributed."""
    m = re.fullmatch(r"([A-Za-z0-9_.-]+)(?:\[([^\]]*)\])?.*", requirement)
    extras = [e.strip() for e in (m.group(2) or "").split(",") if e.strip()]
    return [m.group(1).replace("-", "_").lower(), *extras]


def test_extras_match_pyproject():
    optional = PYPROJECT["project"]["optional-dependencies"]
    for extra, modules in EXTRAS.items():
        provided = [mod for req in optional[extra] for mod in _modules(req)]
        assert sorted(provided) == sorted(modules), extra
    # dev installs everything the test suite needs, every extra included
    dev = " ".join(optional["dev"])
    assert all(extra in dev for extra in EXTRAS)
    assert {"pytest", "hypothesis", "ruff", "build", "twine"} <= {
        _modules(r)[0] for r in optional["dev"]
    }


def test_base_install_is_the_six_libraries_and_numba():
    names = {_modules(r)[0] for r in PYPROJECT["project"]["dependencies"]}
    assert names == BASE
    # every report calls control.linfnorm, which needs slycot: control's own extra
    assert any(r.startswith("control[slycot]") for r in PYPROJECT["project"]["dependencies"])


def test_a_missing_extra_is_a_typed_error_naming_it():
    with pytest.raises(MissingExtraError, match=r"pip install 'bwdesign\[sweep\]'") as info:
        require("bwdesign_no_such_module", extra="sweep", feature="a parameter sweep")
    err = info.value
    assert isinstance(err, ImportError) and err.extra == "sweep"
    assert err.module == err.name == "bwdesign_no_such_module"
    assert "a parameter sweep needs the optional dependency" in str(err)
    assert require("json", extra="sweep", feature="x") is json
    with pytest.raises(ValueError, match="unknown extra 'nope'; extras are browser, docs, sweep"):
        require("json", extra="nope", feature="x")


def test_a_missing_extra_on_the_command_line_is_one_error_line(monkeypatch, capsys):
    def run(args):
        require("bwdesign_no_such_module", extra="sweep", feature="bwdesign sweep")
        return 0

    command = ("needs-extra", "a feature with an optional dependency", lambda p: None, run)
    monkeypatch.setattr(main_mod, "COMMANDS", [*main_mod.COMMANDS, command])
    assert main_mod.main(["needs-extra"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (
        "error: bwdesign sweep needs the optional dependency 'bwdesign_no_such_module', "
        "which is not installed: pip install 'bwdesign[sweep]'\n"
    )


# -- the distributions and a fresh install (slow) -----------------------------


def _need_tools():
    missing = [m for m in ("build", "twine") if find_spec(m) is None]
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"CI must run the install check, but {missing} are missing (.[dev])")
        pytest.skip(f"needs {missing} (pip install -e '.[dev]')")


def _run(cmd, *, cwd, env=None, check=True):
    proc = subprocess.run(
        [str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )
    if check and proc.returncode != 0:
        pytest.fail(f"{cmd} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}")
    return proc


@pytest.fixture(scope="module")
def dists(tmp_path_factory):
    _need_tools()
    out = tmp_path_factory.mktemp("dist")
    _run([sys.executable, "-m", "build", "--outdir", out, ROOT], cwd=ROOT)
    (sdist,) = out.glob("bwdesign-*.tar.gz")
    (wheel,) = out.glob("bwdesign-*-py3-none-any.whl")
    return sdist, wheel


@pytest.mark.slow
def test_distributions_are_complete_and_pass_twine(dists):
    sdist, wheel = dists
    _run([sys.executable, "-m", "twine", "check", "--strict", sdist, wheel], cwd=ROOT)
    ver = version("bwdesign")
    assert ver == PYPROJECT["project"]["version"]
    assert wheel.name == f"bwdesign-{ver}-py3-none-any.whl"

    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        for f in STAGE_FILES:
            assert z.read(f"bwdesign/model/stages/{f}") == (STAGES_DIR / f).read_bytes()
        meta = z.read(f"bwdesign-{ver}.dist-info/METADATA").decode()
    assert f"bwdesign-{ver}.dist-info/licenses/LICENSE" in names
    assert "bwdesign/py.typed" in names and "bwdesign/cli/init.py" in names
    assert not [n for n in names if n.startswith(("configs/", "tests/", "reports/"))]

    assert "License-Expression: MIT" in meta and "Requires-Python: >=3.11" in meta
    assert "Description-Content-Type: text/markdown" in meta and "## Install" in meta
    assert "Classifier: Programming Language :: Python :: 3.11" in meta
    assert re.search(r"^Project-URL: Paper, https://doi\.org/", meta, re.MULTILINE)
    base = set(re.findall(r"^Requires-Dist: ([A-Za-z0-9_-]+)[^;\n]*$", meta, re.MULTILINE))
    assert base == BASE
    assert set(re.findall(r"^Provides-Extra: (\S+)", meta, re.MULTILINE)) == {*EXTRAS, "dev"}

    with tarfile.open(sdist) as t:
        members = t.getmembers()
    top = f"bwdesign-{ver}/"
    rel = [m.name.removeprefix(top) for m in members]
    assert not [m.name for m in members if m.issym() or m.islnk()]
    assert sorted(n for n in rel if n.endswith(".toml") and n != "pyproject.toml") == [
        f"bwdesign/model/stages/{f}" for f in STAGE_FILES
    ]
    assert {"LICENSE", "README.md", "pyproject.toml", "PKG-INFO", "docs/design.md"} <= set(rel)
    assert not [n for n in rel if n.split("/")[0] in ("configs", "tests", "reports")]


def _fresh_env(venv_dir: Path) -> dict[str, str]:
    """The environment of a user's shell: the new venv first on PATH, nothing of ours."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP")
    }
    env["PATH"] = f"{venv_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["VIRTUAL_ENV"] = str(venv_dir)
    env["PYTHONNOUSERSITE"] = "1"
    return env


_API_SCRIPT = """
import json, bwdesign
cfg = bwdesign.load_config("paper_experiment")
env = cfg.envelope()
rep = bwdesign.certify(cfg.plant, cfg.gains, udot_max=env.udot_max, dt=cfg.dt)
print(json.dumps({"file": bwdesign.__file__, "version": bwdesign.__version__,
                  "presets": sorted(bwdesign.stage_presets()), "best": rep.best,
                  "certify": rep.to_dict()}, allow_nan=False))
"""


def _source_certificate(config_path: Path) -> dict:
    doc = study(load_config(config_path), parts=CERTIFICATE_PARTS).to_dict()
    return json.loads(dump_json(doc))


def _certificate_part(path: Path) -> dict:
    """A report's certificate.json without the report's own sections (REPORT_SECTIONS:
    synthesis per tier, ...; checked in tests/test_report.py), which it must hold."""
    doc = json.loads(path.read_text())
    assert [r["tier"] for r in doc.pop("tier_synthesis")["tiers"]][:3] == [
        "theorem1",
        "lipschitz",
        "sector",
    ]
    return {k: v for k, v in doc.items() if k not in REPORT_SECTIONS}


@pytest.mark.slow
def test_the_wheel_installs_and_does_the_main_job_outside_the_repository(dists, tmp_path):
    _, wheel = dists
    fresh = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True, clear=True).create(fresh)
    py, bw = fresh / "bin" / "python", fresh / "bin" / "bwdesign"
    # the same library versions as this environment: the certificates are comparable
    pins = tmp_path / "constraints.txt"
    pins.write_text(
        "".join(
            f"{d.metadata['Name']}=={d.version}\n"
            for d in distributions()
            if d.metadata["Name"] and d.metadata["Name"].lower() not in ("bwdesign", "pip")
        )
    )
    work = tmp_path / "work"
    work.mkdir()
    env = _fresh_env(fresh)
    _run([py, "-m", "pip", "install", "--quiet", wheel, "-c", pins], cwd=work, env=env)

    # not editable, not the source tree: the module comes from the new venv
    api = json.loads(_run([py, "-c", _API_SCRIPT], cwd=work, env=env).stdout)
    assert Path(api["file"]).is_relative_to(fresh) and not Path(api["file"]).is_relative_to(ROOT)
    assert api["version"] == version("bwdesign")
    assert api["presets"] == [f.removesuffix(".toml") for f in STAGE_FILES]
    source = load_config("paper_experiment")
    from bwdesign import certify

    src_rep = certify(source.plant, source.gains, udot_max=source.envelope().udot_max, dt=source.dt)
    assert api["best"] == src_rep.best == "sampled"
    assert api["certify"] == json.loads(dump_json(src_rep.to_dict()))

    ver = _run([bw, "--version"], cwd=work, env=env).stdout.strip()
    assert ver == f"bwdesign {version('bwdesign')}"
    presets = _run([bw, "presets"], cwd=work, env=env).stdout.splitlines()
    # every bundled stage, and the parameter-only presets beside them (one catalogue)
    listed = [line.split()[0] for line in presets]
    assert set(api["presets"]) <= set(listed) and listed == sorted(listed)
    assert set(listed) - set(api["presets"]) == set(bwdesign.PRESETS) - set(api["presets"])

    # the three commands of the README
    out = _run([bw, "init", "stage.toml"], cwd=work, env=env).stdout
    assert out == "wrote stage.toml; next: bwdesign report --config stage.toml --out report\n"
    first, rest = (work / "stage.toml").read_text().split("\n", 1)
    assert first.startswith("# written by bwdesign") and rest == starter_config()
    again = _run([bw, "init", "stage.toml"], cwd=work, env=env, check=False)
    assert (
        again.returncode == 2
        and again.stderr.startswith("error: ")
        and "already exists; not overwritten" in again.stderr
    )
    for config, out_dir in (("stage.toml", "report"), ("paper_experiment", "preset")):
        run = _run(
            [bw, "report", "--config", config, "--out", out_dir, "--quiet"], cwd=work, env=env
        )
        assert run.stdout.startswith(f"{out_dir}/report.md: ")
        md = (work / out_dir / "report.md").read_text()
        assert f"| bwdesign | {version('bwdesign')} |" in md  # the report records the version
    assert sorted(p.name for p in work.iterdir()) == ["preset", "report", "stage.toml"]

    # the same certificate as the source tree's for the same config
    installed = _certificate_part(work / "report" / "certificate.json")
    assert installed == _source_certificate(work / "stage.toml")
    # the starter has its [observer] gains active (it passes its own check): certified
    assert installed["configured"]["certificates"][-1]["holds"]
    assert installed["synthesis"]["feasible"]
    installed = _certificate_part(work / "preset" / "certificate.json")
    assert installed == _source_certificate(ROOT / "configs" / "paper_experiment.toml")
    assert installed["configured"]["certificates"][-1]["holds"]

    # the base install has no sweep extra: the feature names it instead of an ImportError
    missing = _run(
        [
            py,
            "-c",
            "from bwdesign.extras import require; require('dask', extra='sweep', feature='s')",
        ],
        cwd=work,
        env=env,
        check=False,
    )
    assert missing.returncode == 1
    assert "MissingExtraError: s needs the optional dependency 'dask'" in missing.stderr
    assert "pip install 'bwdesign[sweep]'" in missing.stderr
