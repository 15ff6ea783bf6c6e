"""Fuzzing the command line: generated stage files and argument lists, run in-process.

Hypothesis (derandomized, see conftest.py) generates stage TOML files (wrong
types, missing and unknown keys and sections, extreme and non-finite numbers,
bad UTF-8, oversized files) and argument lists for every subcommand, and runs
``bwdesign.cli.main`` on them inside a directory that also holds a user's file,
a directory with a user's notes, a FIFO and a symlink. Whatever the input:

- the exit code is 0, 1 or 2, and no numpy ``RuntimeWarning`` is raised;
- on 2, stderr ends in exactly one ``error:`` line, holds no traceback, no
  warning was raised at all, and nothing in the directory changed;
- on 0 or 1, the user's files are byte-for-byte intact.

The default run keeps ``max_examples`` small (a few seconds); the
``slow``-marked variants run the same properties with more examples and also
report on valid files (about a minute; ``BWDESIGN_FUZZ_SCALE=N`` multiplies
their examples).
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import stat
import tomllib
import warnings
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bwdesign.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
GOOD = tomllib.loads((ROOT / "configs" / "paper_experiment.toml").read_text())
USER = b"a user's notes\n"
QUICK = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
#: ``BWDESIGN_FUZZ_SCALE=10 pytest -m slow tests/test_fuzz.py`` runs ten times more examples.
SCALE = max(1, int(os.environ.get("BWDESIGN_FUZZ_SCALE", "1")))
SLOW = settings(max_examples=100 * SCALE, deadline=None, suppress_health_check=list(HealthCheck))


# -- running the CLI -------------------------------------------------------------


def _snapshot(path: Path) -> dict[str, object]:
    out: dict[str, object] = {}
    for p in sorted(path.rglob("*")):
        st_ = os.lstat(p)
        key = p.relative_to(path).as_posix()
        out[key] = p.read_bytes() if stat.S_ISREG(st_.st_mode) else stat.filemode(st_.st_mode)
    return out


def _workdir(base: Path) -> Path:
    """A fresh directory with a user's file, a user's directory, a FIFO and a symlink."""
    n = 0
    while (base / f"w{n}").exists():
        n += 1
    w = base / f"w{n}"
    w.mkdir()
    (w / "notes.txt").write_bytes(USER)
    (w / "mydir").mkdir()
    (w / "mydir" / "notes.txt").write_bytes(USER)
    os.mkfifo(w / "pipe")
    (w / "link").symlink_to(w / "notes.txt")
    return w


def check_cli(workdir: Path, argv: list[str]) -> int:
    """Run ``main(argv)`` in ``workdir`` and check the rules of the module docstring."""
    before = _snapshot(workdir)
    out, err = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        with (
            warnings.catch_warnings(record=True) as caught,
            contextlib.redirect_stdout(out),
            contextlib.redirect_stderr(err),
        ):
            warnings.simplefilter("always")
            code = main(argv)
    finally:
        os.chdir(cwd)
    text = err.getvalue()
    assert code in (0, 1, 2), (argv, code, text)
    assert "Traceback" not in text, (argv, text)
    runtime = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert not runtime, (argv, runtime)
    if code == 2:
        lines = text.splitlines()
        assert lines and lines[-1].startswith("error: "), (argv, text)
        assert sum(ln.startswith("error: ") for ln in lines) == 1, (argv, text)
        assert not caught, (argv, [str(w.message) for w in caught])
        assert _snapshot(workdir) == before, (argv, "something was written")
    for rel in ("notes.txt", "mydir/notes.txt"):
        assert (workdir / rel).read_bytes() == USER, (argv, rel)
    assert stat.S_ISFIFO(os.lstat(workdir / "pipe").st_mode)
    assert (workdir / "link").is_symlink()
    return code


# -- stage TOML files ----------------------------------------------------------------

EXTREME = [0, -0.0, 1e308, -1e308, 5e-324, 1e-300, 1e300, 1e15, -1e15, 2**63 - 1, -(2**63)]
scalars = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(EXTREME),
    st.integers(-(2**63), 2**63 - 1),
    st.booleans(),
    st.text(max_size=6),
)
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4), max_leaves=6)
#: Mostly plausible numbers, so that some mutated files pass validation and run.
mutations = st.one_of(st.floats(1e-3, 1e6), st.floats(1e-3, 1e6), values)


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return '"' + "".join(c if c.isprintable() and c not in '"\\' else
                             f"\\u{ord(c):04x}" for c in v) + '"'  # fmt: skip
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(v)


def toml_dumps(doc: dict[str, object]) -> str:
    head = [f"{k} = {_toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    body = []
    for k, v in doc.items():
        if isinstance(v, dict):
            body.append(f"[{k}]")
            body += [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
    return "\n".join(head + body) + "\n"


@st.composite
def stage_files(draw) -> bytes:
    """A mutated copy of the paper_experiment stage, as bytes."""
    doc = {k: dict(v) for k, v in GOOD.items()}
    keys = [(s, k) for s, t in doc.items() for k in t]
    for s, k in draw(st.lists(st.sampled_from(keys), max_size=4, unique=True)):
        action = draw(st.sampled_from(["value", "value", "delete"]))
        if action == "delete":
            doc[s].pop(k, None)
        else:
            doc[s][k] = draw(mutations)
    sections = st.lists(st.sampled_from(sorted(doc)), max_size=2, unique=True)
    for s in draw(sections) if draw(st.integers(0, 3)) == 0 else []:
        if draw(st.booleans()):
            del doc[s]
        else:
            doc[s] = draw(values)  # a section that is not a table
    if draw(st.integers(0, 3)) == 0:
        section = draw(st.sampled_from([*sorted(GOOD), "plotting"]))
        doc.setdefault(section, {})
        if isinstance(doc[section], dict):
            doc[section][draw(st.sampled_from(["mass", "kind", "extra", "dt", "a1"]))] = draw(
                values
            )
    text = toml_dumps(doc).encode()
    if draw(st.integers(0, 9)) == 0:  # bytes that are not UTF-8, or not TOML at all
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(st.binary(min_size=1, max_size=8)) + text[at:]
    return text


SIM = [
    "--gains", "8,64,-512", "--amplitude", "80", "--offset", "100", "--frequency", "1",
    "--lambda1", "1", "--lambda2", "2", "--dt", "2e-4", "--duration", "0.004",
]  # fmt: skip


def _stage_props(tmp_path: Path, data: bytes, *, report: bool = False) -> None:
    w = _workdir(tmp_path)
    (w / "stage.toml").write_bytes(data)
    check_cli(w, ["params", "--plant", "stage.toml", "--json"])
    check_cli(w, ["simulate", "--plant", "stage.toml", *SIM, "--csv", "out.csv"])
    check_cli(w, ["certify", "--plant", "stage.toml", "--gains", "8,64,-512", "--udot-max", "50"])
    if report:  # seconds per valid file
        check_cli(w, ["report", "--config", "stage.toml", "--out", "rep", "--quiet"])


@QUICK
@given(data=stage_files())
def test_generated_stage_files(tmp_path_factory, data):
    _stage_props(tmp_path_factory.mktemp("stage"), data)


@pytest.mark.slow
@settings(SLOW, max_examples=25 * SCALE)
@given(data=stage_files())
def test_generated_stage_files_many(tmp_path_factory, data):
    _stage_props(tmp_path_factory.mktemp("stage"), data, report=True)


def test_oversized_stage_file(tmp_path):
    w = _workdir(tmp_path)
    (w / "stage.toml").write_bytes(b"# padding\n" * 200_000)
    assert check_cli(w, ["params", "--plant", "stage.toml"]) == 2


# -- argument lists ---------------------------------------------------------------

PLAUSIBLE = st.floats(1e-3, 1e3).map(lambda x: f"{x:.4g}")
NUMBERS = st.one_of(
    PLAUSIBLE,
    PLAUSIBLE,
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(
        [
            "1e308",
            "-1e308",
            "1e-320",
            "0",
            "-0",
            "nan",
            "inf",
            "0x10",
            "",
            " ",
            "1,2,3",
            "\u0661",
            "1_000",
            "3.0",
            "-3",
            "2e-4",
            "361",
            "1",
        ]
    ),  # fmt: skip
    st.integers(-(10**30), 10**30).map(str),
)
#: Sample times and durations: plausible (and short to simulate) or invalid.
DT = st.one_of(st.sampled_from(["1e-4", "2e-4", "5e-4", "1", "0", "-1", "nan", "1e-12"]), NUMBERS)
DURATION = st.one_of(st.floats(1e-3, 0.02).map(repr), st.sampled_from(["0", "-1", "inf", "x"]))
GAINS = st.one_of(
    st.sampled_from(["8,64,-512", "80,160,-640", "8,64,512", "1,2", "a,b,c", "nan,1,1"]),
    st.lists(NUMBERS, min_size=1, max_size=4).map(",".join),
)
PATHS = st.sampled_from(
    ["out", "out.csv", "", ".", "notes.txt", "mydir", "pipe", "link", "mydir/new", "no/dir/x"]
)
PLANTS = st.sampled_from(
    ["paper_experiment", "paper_simulation", "paper_simulation_corrected", "nope", "pipe",
     "notes.txt", "mydir", "", str(ROOT / "configs" / "stack_actuator_800hz.toml")]
)  # fmt: skip

COMMON = {"--plant": PLANTS, "--allow-unbounded": None, "--json": None}
OPTIONS: dict[str, dict[str, st.SearchStrategy[str] | None]] = {
    "params": COMMON,
    "certify": {
        **COMMON,
        "--gains": GAINS,
        "--udot-max": NUMBERS,
        "--decay": NUMBERS,
        "--dt": DT,
    },
    "synthesize": {
        **COMMON,
        "--udot-max": NUMBERS,
        "--decay": NUMBERS,
        "--dt": DT,
        "--pole-radius": NUMBERS,
    },
    "simulate": {
        **COMMON,
        "--reference": st.sampled_from(["sine", "triangle", "step", "saw"]),
        "--amplitude": NUMBERS,
        "--offset": NUMBERS,
        "--frequency": NUMBERS,
        "--phase": NUMBERS,
        "--rise-time": NUMBERS,
        "--t-step": NUMBERS,
        "--observer": st.sampled_from(["phso", "eso", "ukf", "kf"]),
        "--gains": GAINS,
        "--lambda1": NUMBERS,
        "--lambda2": NUMBERS,
        "--form": st.sampled_from(["continuous", "discrete", "zoh"]),
        "--integral-rate": NUMBERS,
        "--dt": DT,
        "--duration": DURATION,
        "--noise-std": NUMBERS,
        "--seed": NUMBERS,
        "--delay": None,
        "--u-min": NUMBERS,
        "--u-max": NUMBERS,
        "--true-plant": PLANTS,
        "--csv": PATHS,
    },
    "report": {
        "--config": st.sampled_from(["notes.txt", "pipe", "mydir", "absent.toml", ""]),
        # (a valid config takes seconds to report on: only in the slow variant, below)
        "--out": PATHS,
        "--quiet": None,
        "--allow-unbounded": None,
        "--force": None,
    },
}
#: Values that make a run valid (so it gets past the parser) and short.
BASE = {
    "certify": ["--plant", "paper_experiment", "--gains", "8,64,-512", "--udot-max", "361"],
    "synthesize": ["--plant", "paper_experiment", "--udot-max", "400"],
    "simulate": ["--plant", "paper_experiment", *SIM],
    "params": ["--plant", "paper_experiment"],
    "report": ["--config", "notes.txt", "--out", "out"],
}


#: The slow variant also reports on a valid stage file (seconds per run).
SLOW_OPTIONS = {
    **OPTIONS,
    "report": {
        **OPTIONS["report"],
        "--config": st.sampled_from(["notes.txt", str(ROOT / "configs" / "paper_experiment.toml")]),
    },
}


@st.composite
def argv_for(draw, command: str, options=OPTIONS) -> list[str]:
    """A valid base argument list with 1-4 options changed to generated values."""
    opts = options[command]
    argv = [command]
    chosen = draw(st.lists(st.sampled_from(sorted(opts)), min_size=1, max_size=4, unique=True))
    base = BASE[command]
    pairs = dict(zip(base[::2], base[1::2], strict=True))
    for name in chosen:
        pairs.pop(name, None)
    for name, value in pairs.items():
        argv += [name, value]
    for name in chosen:
        strategy = opts[name]
        argv += [name] if strategy is None else [name, draw(strategy)]
    if draw(st.integers(0, 9)) == 0:
        argv.insert(draw(st.integers(1, len(argv))), draw(st.sampled_from(["--bogus", "-x"])))
    return argv


def _argv_props(tmp_path: Path, argv: list[str]) -> None:
    check_cli(_workdir(tmp_path), argv)


# certify/synthesize that pass validation solve LMIs (~1 s each): fewer examples
QUICK_CERT = settings(QUICK, max_examples=30)


@pytest.mark.parametrize("command", sorted(OPTIONS))
def test_generated_argument_lists(tmp_path_factory, command):
    quick = QUICK_CERT if command in ("certify", "synthesize") else QUICK

    @quick
    @given(argv=argv_for(command))
    def run(argv):
        _argv_props(tmp_path_factory.mktemp(command), argv)

    run()


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(OPTIONS))
def test_generated_argument_lists_many(tmp_path_factory, command):
    @settings(SLOW, max_examples=(10 if command == "report" else 100) * SCALE)
    @given(argv=argv_for(command, SLOW_OPTIONS))
    def run(argv):
        _argv_props(tmp_path_factory.mktemp(command), argv)

    run()
