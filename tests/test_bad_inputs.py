"""A named table of bad inputs: each one exit 2, one ``error:`` line, nothing written.

Every case runs ``bwdesign.cli.main`` in-process from inside ``tmp_path``;
the files a case needs (stage TOML files, a user's notes, a FIFO, a symlink,
a read-only file, a locked directory) are made there by the test. Checked for
each: exit code 2, nothing on stdout, the last stderr line starts with
``error:`` and is the only such line, no ``Traceback`` and no ``Warning`` on
stderr, no warning raised (recorded: under pytest warnings never reach stderr),
and the directory holds exactly what it held before.

``python tests/test_bad_inputs.py`` prints the table with each case's error line.
"""

from __future__ import annotations

import math
import os
import stat
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from bwdesign import (
    BoucWenParams,
    ClosedLoop,
    HysteresisObserver,
    ObserverSpec,
    Sine,
    Start,
    UncertaintyBox,
    UnscentedObserver,
    certify,
    make_controller,
    preset,
    simulate,
    synthesize,
)
from bwdesign.certify.disturbance import certify_disturbance
from bwdesign.certify.robust_observer import BoxSampling, certify_robust_observer
from bwdesign.cli.main import main
from bwdesign.control.controllers import TrackingController
from bwdesign.design.robust import RobustSearch, synthesize_robust
from bwdesign.design.tuning import MarginRequirements, digital_tuning
from bwdesign.errors import ConfigError, GainError, InputError, ParameterError
from bwdesign.extras import require
from bwdesign.identify import IdentificationData, identify, load_data
from bwdesign.identify.excite import design_excitation
from bwdesign.model.config import load_config
from bwdesign.model.plant import simulate_zoh
from bwdesign.model.requirements import parse_requirements
from bwdesign.sim import simulate_batch
from bwdesign.validate import DT, SEED, integer, parse_real, real

ROOT = Path(__file__).resolve().parents[1]
GOOD_TOML = (ROOT / "configs" / "paper_experiment.toml").read_text()
PLANT = """[plant]
name = "t"
a1 = 159827.5
a2 = 713.8
a3 = 222665.02
alpha = 0.4795
beta = 0.3762
gamma = 0.0378
"""
GAINS = ["--gains", "8,64,-512"]
CERT = ["certify", "--plant", "paper_experiment", *GAINS, "--udot-max", "361"]
SYN = ["synthesize", "--plant", "paper_experiment", "--udot-max", "400"]
SIM = [
    "simulate", "--plant", "paper_experiment", *GAINS, "--amplitude", "80", "--offset", "100",
    "--frequency", "1", "--lambda1", "1", "--lambda2", "2", "--dt", "2e-4", "--duration", "0.01",
]  # fmt: skip
REPORT = ["report", "--config", "stage.toml", "--out", "rep", "--quiet"]


def sim(**changes: str) -> list[str]:
    """``SIM`` with some options changed (``u_min="5"`` sets ``--u-min 5``)."""
    argv = list(SIM)
    for key, value in changes.items():
        opt = "--" + key.replace("_", "-")
        if opt in argv:
            argv[argv.index(opt) + 1] = value
        else:
            argv += [opt, value]
    return argv


def _stage(text: str | bytes) -> Callable[[Path], None]:
    def make(tmp: Path) -> None:
        data = text.encode() if isinstance(text, str) else text
        (tmp / "stage.toml").write_bytes(data)

    return make


def _good(tmp: Path) -> None:
    _stage(GOOD_TOML)(tmp)


def _user_dir(tmp: Path) -> None:
    _good(tmp)
    (tmp / "mydir").mkdir()
    (tmp / "mydir" / "notes.txt").write_text("my notes\n")


def _user_file(tmp: Path) -> None:
    _good(tmp)
    (tmp / "afile").write_text("my file\n")


def _symlinks(tmp: Path) -> None:
    _good(tmp)
    (tmp / "real.csv").write_text("my data\n")
    (tmp / "link.csv").symlink_to(tmp / "real.csv")
    (tmp / "realdir").mkdir()
    (tmp / "linkdir").symlink_to(tmp / "realdir", target_is_directory=True)


def _fifo(tmp: Path) -> None:
    os.mkfifo(tmp / "pipe")


def _read_only(tmp: Path) -> None:
    (tmp / "ro.csv").write_text("# written by bwdesign 0 (simulate --csv) sha256=0\n")
    (tmp / "ro.csv").chmod(0o444)


def _locked(tmp: Path) -> None:
    _good(tmp)
    (tmp / "locked").mkdir()
    (tmp / "locked").chmod(0o555)


def _replace(old: str, new: str) -> Callable[[Path], None]:
    assert old in GOOD_TOML, old
    return _stage(GOOD_TOML.replace(old, new))


def _plant(old: str, new: str, extra: str = "") -> Callable[[Path], None]:
    assert old in PLANT, old
    return _stage(PLANT.replace(old, new) + extra)


SWEEP = [
    "sweep",
    "--config",
    "stage.toml",
    "--out",
    "sw",
    "--uncertainty",
    "a1=2%",
    "--samples",
    "3",
]
SWEPT = GOOD_TOML + "[uncertainty]\na1 = { rel = 0.02 }\n\n[sweep]\nsamples = 4\n"


def sweep_box(text: str) -> list[str]:
    """``SWEEP`` with ``--uncertainty TEXT``."""
    return [*SWEEP[:-3], text, *SWEEP[-2:]]


def _boxed(box: str, name: str = "stage.toml") -> Callable[[Path], None]:
    """The good stage with ``[uncertainty]`` ``box`` (as ``name``; stage.toml also written)."""

    def make(tmp: Path) -> None:
        _good(tmp)
        (tmp / name).write_text(GOOD_TOML + "[uncertainty]\n" + box + "\n")

    return make


def _record(*, u: float | None = None, y: float | None = None, dt: float = 1e-3):
    """A record ``rec.csv`` (400 samples) with u = +-u (alternating) or y = y when given."""

    def make(tmp: Path) -> None:
        k = np.arange(400)
        uu = np.where(k % 2, u, -u) if u is not None else 5 + 4 * np.sin(0.05 * k)
        yy = np.full(400, y) if y is not None else 1.4 * uu
        rows = "\n".join(
            f"{i * dt!r},{a!r},{b!r}"
            for i, a, b in zip(k.tolist(), uu.tolist(), yy.tolist(), strict=True)
        )
        (tmp / "rec.csv").write_text("t,u,y\n" + rows + "\n")

    return make


def _second_record(*, nan_row: int | None = None, gap_after: int | None = None):
    """A good ``rec.csv`` and a second record ``rec2.csv`` at another sample rate with a NaN at
    data row ``nan_row`` or a gap in t after data row ``gap_after``."""

    def make(tmp: Path) -> None:
        _record()(tmp)
        k = np.arange(500)
        t = k * 2e-4 + np.where(k >= (gap_after or 10**9), 5 * 2e-4, 0.0)
        u = 5 + 4 * np.sin(0.02 * k)
        y = 1.4 * u
        if nan_row is not None:
            y[nan_row - 1] = np.nan
        cols = zip(t.tolist(), u.tolist(), y.tolist(), strict=True)
        rows = "\n".join(f"{a!r},{b!r},{c!r}" for a, b, c in cols)
        (tmp / "rec2.csv").write_text("t,u,y\n" + rows + "\n")

    return make


def _with_record(setup: Callable[[Path], None]) -> Callable[[Path], None]:
    def make(tmp: Path) -> None:
        setup(tmp)
        _record()(tmp)

    return make


IDENT = ["identify", "--data", "rec.csv", "--out", "id.toml", "--quiet"]
EXCITE = ["excite", "--plant", "paper_experiment", "--umin", "0", "--umax", "120"]
EXCITE += ["--udot-max", "1e-6", "--duration", "1", "--dt", "1e-3", "--out", "e.csv"]
STAGE = ["--plant", "stage.toml"]
CERT_STAGE = ["certify", *STAGE, *GAINS, "--udot-max", "361"]
ENV = "from_reference = true\nmargin = 1.1"

#: (name, argv, setup, part of the error line)
CASES: list[tuple[str, list[str], Callable[[Path], None] | None, str]] = [
    # -- the cases -----------------------------------------------------
    ("report into a dir with a user's file", [*REPORT[:4], "mydir"], _user_dir, "notes.txt"),
    ("report into a plain file", [*REPORT[:4], "afile"], _user_file, "not a directory"),
    ("report --out .", [*REPORT[:4], "."], _good, "current directory"),
    ("report --out ''", [*REPORT[:4], ""], _good, "empty path"),
    ("report --out in a locked dir", [*REPORT[:4], "locked/x"], _locked, "not writable"),
    ("report --out below a file", [*REPORT[:4], "afile/sub"], _user_file, "not a directory"),
    ("simulate --csv below a file", [*SIM, "--csv", "afile/x.csv"], _user_file, "not a directory"),
    ("report --out symlink", [*REPORT[:4], "linkdir"], _symlinks, "symbolic link"),
    ("report --out FIFO", [*REPORT[:4], "pipe", "--force"], _fifo, "FIFO"),
    ("simulate --seed -3", [*SIM, "--seed", "-3"], None, "seed = -3 is outside"),
    ("simulate --seed 1.5", [*SIM, "--seed", "1.5"], None, "expected an integer"),
    ("certify a1 = 1e308", CERT_STAGE, _plant("a1 = 159827.5", "a1 = 1e308"), "a1 = 1e+308"),
    ("simulate --csv symlink", [*SIM, "--csv", "link.csv"], _symlinks, "symbolic link"),
    ("simulate --csv read-only", [*SIM, "--csv", "ro.csv"], _read_only, "read-only"),
    ("simulate --csv FIFO", [*SIM, "--csv", "pipe"], _fifo, "FIFO"),
    ("simulate --csv user's file", [*SIM, "--csv", "afile"], _user_file, "never overwrites"),
    ("simulate --csv ''", [*SIM, "--csv", ""], None, "empty path"),
    ("simulate --csv a directory", [*SIM, "--csv", "mydir"], _user_dir, "directory"),
    ("simulate --csv in a locked dir", [*SIM, "--csv", "locked/x.csv"], _locked, "not writable"),
    ("simulate --csv missing dir", [*SIM, "--csv", "nodir/x.csv"], None, "does not exist"),
    ("certify --udot-max 1e300", [*CERT[:-1], "1e300"], None, "udot_max (V/s) = 1e+300"),
    ("synthesize --udot-max 1e300", [*SYN[:-1], "1e300"], None, "udot_max (V/s) = 1e+300"),
    ("certify --dt 1", [*CERT, "--dt", "1"], None, "dt = 1 s is too long"),
    ("simulate --dt 1", sim(dt="1", duration="10"), None, "too long"),
    ("report dt = 1 in TOML", REPORT, _replace("dt = 0.0002", "dt = 1.0"), "too long"),
    # -- kept from before: already clean ---------------------------------------
    ("unknown preset", ["params", "--plant", "no_such_stage"], None, "unknown plant preset"),
    ("empty --plant", ["params", "--plant", ""], None, "unknown plant preset ''"),
    ("empty --config", [*REPORT[:2], "", *REPORT[3:]], None, "empty path"),
    ("missing key", ["params", *STAGE], _plant("a2 = 713.8\n", ""), "missing field(s) a2"),
    ("negative dt", [*CERT, "--dt", "-1"], None, "expected a positive number"),
    (
        "malformed gains",
        ["certify", "--plant", "paper_experiment", "--gains", "1,2", "--udot-max", "361"],
        None,
        "three comma-separated",
    ),  # fmt: skip
    (
        "unbounded parameters",
        ["certify", "--plant", "paper_simulation", *GAINS, "--udot-max", "1"],
        None,
        "outside the bounded",
    ),  # fmt: skip
    # -- more ranges and types -------------------------------------------------
    ("certify --dt 1e-12", [*CERT, "--dt", "1e-12"], None, "dt (s) = 1e-12 is outside"),
    ("certify --decay 1e300", [*CERT, "--decay", "1e300"], None, "decay (1/s) = 1e+300"),
    ("synthesize --pole-radius 1e300", [*SYN, "--pole-radius", "1e300"], None, "pole_radius"),
    (
        "certify gain 1e300",
        ["certify", "--plant", "paper_experiment", "--gains", "8,64,-1e300", "--udot-max", "361"],
        None,
        "supported range",
    ),  # fmt: skip
    (
        "certify gain nan",
        ["certify", "--plant", "paper_experiment", "--gains", "nan,64,-512", "--udot-max", "361"],
        None,
        "finite",
    ),  # fmt: skip
    ("simulate --amplitude 1e300", sim(amplitude="1e300"), None, "amplitude = 1e+300"),
    ("simulate --frequency 1e300", sim(frequency="1e300"), None, "frequency = 1e+300"),
    ("simulate --lambda1 0", sim(lambda1="0"), None, "expected a positive number"),
    ("simulate --noise-std -1", [*SIM, "--noise-std", "-1"], None, "expected a number >= 0"),
    ("simulate --u-min > --u-max", [*SIM, "--u-min", "5", "--u-max", "1"], None, "u_min < u_max"),
    ("simulate --offset nan", sim(offset="nan"), None, "expected a finite number"),
    ("simulate --duration 1e300", sim(duration="1e300"), None, "exceeds the limit"),
    (
        "simulate unbounded --true-plant",
        [*SIM, "--true-plant", "paper_simulation"],
        None,
        "outside the bounded",
    ),
    ("a3 = 1e-300", ["params", *STAGE], _plant("a3 = 222665.02", "a3 = 1e-300"), "|a3|"),
    ("beta = 1e300", ["params", *STAGE], _plant("beta = 0.3762", "beta = 1e300"), "beta = 1e+300"),
    (
        "physical m = 1e-300",
        ["params", *STAGE],
        _stage(
            "[plant]\nm = 1e-300\nb = 1.0\nk = 1.0\nd = 1.0\nalpha0 = 1.0\n"
            "beta = 0.2\ngamma = 0.1\n"
        ),
        "m = 1e-300",
    ),  # fmt: skip
    ("a1 is a bool", ["params", *STAGE], _plant("a1 = 159827.5", "a1 = true"), "a1 must be"),
    ("a1 is a string", ["params", *STAGE], _plant("a1 = 159827.5", 'a1 = "1e5"'), "a1 must be"),
    (
        "reference kind is a list",
        ["params", *STAGE],
        _plant("gamma = 0.0378", "gamma = 0.0378", "[reference]\nkind = [1]\namplitude = 1.0\n"),
        "kind must be one of",
    ),  # fmt: skip
    ("bad UTF-8", ["params", *STAGE], _stage(b'[plant]\nname = "\xff\xfe"\n'), "malformed TOML"),
    ("stage file is a directory", ["params", "--plant", "mydir"], _user_dir, "not a regular"),
    ("stage file is a FIFO", ["params", "--plant", "pipe"], _fifo, "not a regular file"),
    ("huge stage file", ["params", *STAGE], _stage(PLANT + "#" * (1 << 21)), "at most"),
    (
        "huge gains list",
        ["params", *STAGE],
        _stage(PLANT + "[observer]\ngains = [" + "1.0, " * 50000 + "]\n"),
        "gains must be a list of 3 numbers",
    ),
    (
        "report udot_max 1e300",
        REPORT,
        _replace(ENV, "udot_max = 1e300"),
        "[envelope] udot_max (input unit/s) = 1e+300 is outside the supported range",
    ),
    ("report margin 1e300", REPORT, _replace("margin = 1.1", "margin = 1e300"), "margin"),
    ("report decay -1", REPORT, _stage(GOOD_TOML + "[synthesis]\ndecay = -1.0\n"), "decay"),
    ("report missing config", REPORT, None, "does not exist"),
    (
        "report gains strings",
        REPORT,
        _replace("[8.0, 64.0, -512.0]", '["8", 64, -512]'),
        "gains[0] must be a number",
    ),  # fmt: skip
    ("unknown subcommand", ["frobnicate"], None, "invalid choice"),
    # -- sweep limits (each refused before any work) ---------------------------
    ("sweep --workers 1000", [*SWEEP, "--workers", "1000"], _good, "at most"),
    ("sweep --samples 100000000", [*SWEEP[:-1], "100000000"], _good, "scenarios with 2"),
    ("sweep --scheduler notaurl", [*SWEEP, "--scheduler", "notaurl"], _good, "tcp://HOST:PORT"),
    ("sweep --observers phso,phso", [*SWEEP, "--observers", "phso,phso"], _good, "once"),
    (
        "sweep --uncertainty a1 twice",
        [*SWEEP[:-3], "a1=2%,a1=3%", *SWEEP[-2:]],
        _good,
        "a1 given twice",
    ),  # fmt: skip
    # -- the uncertainty box (issue 25): one parser, one check ------------------------
    ("sweep --uncertainty zeta=2%", sweep_box("zeta=2%"), _good, "expected NAME=WIDTH"),
    ("sweep --uncertainty a1", sweep_box("a1"), _good, "expected NAME=WIDTH"),
    ("sweep --uncertainty a1=x", sweep_box("a1=x"), _good, "a1 half-width must be a number"),
    ("sweep --uncertainty a1=-2%", sweep_box("a1=-2%"), _good, "(%) = -2 is outside"),
    ("sweep --uncertainty a1=inf", sweep_box("a1=inf"), _good, "a1 half-width must be finite"),
    ("sweep --uncertainty ''", sweep_box(""), _good, "--uncertainty: no parameter given"),
    ("sweep --uncertainty beta=95%", sweep_box("beta=95%"), _good, "leaves the bounded class"),
    ("sweep --uncertainty a3=150%", sweep_box("a3=150%"), _good, "a3 must keep its sign"),
    ("sweep --uncertainty a1=200%", sweep_box("a1=200%"), _good, "lets a1 reach"),
    (
        "sweep [uncertainty] a1 inf",
        [*SWEEP[:5], *SWEEP[-2:]],
        _boxed("a1 = { rel = inf }"),
        "leaves a1 not determined",
    ),  # fmt: skip
    (
        "report [sweep] over a box leaving the class",
        REPORT,
        _stage(SWEPT.replace("a1 = { rel = 0.02 }", "beta = { rel = 0.95 }")),
        "leaves the bounded class",
    ),
    (
        "report [sweep] over an undetermined box",
        REPORT,
        _stage(SWEPT.replace("a1 = { rel = 0.02 }", "a1 = { rel = inf }")),
        "leaves a1 not determined",
    ),
    (
        "certify --uncertainty-from an undetermined box",
        [*CERT_STAGE, "--uncertainty-from", "box.toml", "--input-range", "0,150"],
        _boxed("alpha = { abs = inf }", "box.toml"),
        "leaves alpha not determined",
    ),
    (
        "synthesize --robust over a box leaving the class",
        ["synthesize", *STAGE, "--robust"],
        _boxed("beta = { rel = 0.95 }"),
        "leaves the bounded class",
    ),
    (
        "synthesize --robust over an undetermined box",
        ["synthesize", *STAGE, "--robust"],
        _boxed("a3 = { abs = inf }"),
        "leaves a3 not determined",
    ),
    (
        "report [sweep] observers twice",
        REPORT,
        _stage(SWEPT + 'observers = ["eso", "eso"]\n'),
        "once",
    ),
    (
        "report [sweep] samples 0",
        REPORT,
        _stage(SWEPT.replace("samples = 4", "samples = 0")),
        "[sweep] samples = 0 is outside the supported range [1, inf)",
    ),
    (
        "report [sweep] samples 1e8",
        REPORT,
        _stage(SWEPT.replace("samples = 4", "samples = 100000000")),
        "at most",
    ),
    # -- issue 24: edges a new user hit ----------------------------------------------
    (
        "check exit 2 writes no JUnit file",
        ["check", "stage.toml", "--junit-xml", "r.xml"],
        _replace("[observer]\ngains = [8.0, 64.0, -512.0]", ""),
        "needs [observer] gains",
    ),  # fmt: skip
    ("identify u = +-1e300", IDENT, _record(u=1e300), "u at data row 1 (V) = -1e+300 is outside"),
    ("identify y = 1e300", IDENT, _record(y=1e300), "y at data row 1"),
    ("identify dt = 1e-16", IDENT, _record(dt=1e-16), "sample time dt (s) = 1e-16 is outside"),
    ("identify --data a directory", [*IDENT[:2], "mydir", *IDENT[3:]], _user_dir, "is a directory"),
    (
        "identify --report a user's dir",
        [*IDENT, "--report", "mydir"],
        _with_record(_user_dir),
        "pass --force",
    ),  # fmt: skip
    ("identify --force without --report", [*IDENT, "--force"], _record(), "applies to --report"),
    # -- issue 26: several records in one fit: each file's errors name it ------------
    (
        "identify a NaN row in the second --data",
        [*IDENT[:3], "--data", "rec2.csv", *IDENT[3:]],
        _second_record(nan_row=7),
        "rec2.csv: 1 row(s) with NaN or infinite values, first at data row 7",
    ),  # fmt: skip
    (
        "identify a gap in t in the second --data",
        [*IDENT[:3], "--data", "rec2.csv", *IDENT[3:]],
        _second_record(gap_after=300),
        "rec2.csv: a gap in t between data rows 300 and 301",
    ),  # fmt: skip
    (
        "TOML nested 3000 deep",
        ["params", *STAGE],
        _stage(PLANT + "x = " + "[" * 3000 + "]" * 3000),
        "nested too deeply",
    ),  # fmt: skip
    (
        "simulate above Nyquist",
        sim(frequency="3000"),
        None,
        "frequency 3000 Hz is at or above the Nyquist frequency 1/(2 dt) = 2500 Hz",
    ),  # fmt: skip
    ("simulate at Nyquist", sim(frequency="2500"), None, "at or above the Nyquist frequency"),
    (
        "report reference above Nyquist",
        REPORT,
        _replace("frequency = 1.0", "frequency = 2600.0"),
        "[reference] frequency 2600 Hz is at or above the Nyquist frequency",
    ),  # fmt: skip
    ("excite --udot-max 1e-6", EXCITE, None, "below the smallest usable 786 V/s"),
    (
        "--plant error lists every preset",
        ["params", "--plant", "no_such_stage"],
        None,
        "paper_simulation, paper_simulation_corrected, stack_actuator_800hz",
    ),
]


def snapshot(path: Path) -> dict[str, object]:
    out: dict[str, object] = {}
    for p in sorted(path.rglob("*")):
        st = os.lstat(p)
        key = p.relative_to(path).as_posix()
        out[key] = p.read_bytes() if stat.S_ISREG(st.st_mode) else stat.filemode(st.st_mode)
    return out


def run_case(tmp: Path, argv: list[str], setup, capsys) -> tuple[int, str, str]:
    if setup is not None:
        setup(tmp)
    before = snapshot(tmp)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")  # pytest would otherwise swallow them
            code = main(argv)
        assert not caught, [str(w.message) for w in caught]
        out, err = capsys.readouterr()
        assert snapshot(tmp) == before, "something was written"
    finally:
        if (tmp / "locked").exists():
            (tmp / "locked").chmod(0o755)
    return code, out, err


def test_the_table_is_long_enough():
    assert len(CASES) >= 40
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("name, argv, setup, message", CASES, ids=[c[0] for c in CASES])
def test_bad_input(tmp_path, monkeypatch, capsys, name, argv, setup, message):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_case(tmp_path, argv, setup, capsys)
    assert code == 2, err
    assert out == ""
    lines = err.splitlines()
    assert lines and lines[-1].startswith("error: "), err
    assert sum(ln.startswith("error: ") for ln in lines) == 1
    assert "Traceback" not in err and "Warning" not in err
    assert message in lines[-1], lines[-1]


if __name__ == "__main__":  # print the table: input, exit code, error line
    import contextlib
    import io
    import shlex
    import tempfile

    for name, argv, setup, _ in CASES:
        with tempfile.TemporaryDirectory() as d:
            os.chdir(d)
            if setup is not None:
                setup(Path(d))
            err = io.StringIO()
            try:
                with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                    code = main(argv)
            finally:
                if (Path(d) / "locked").exists():
                    (Path(d) / "locked").chmod(0o755)
                os.chdir(ROOT)
            line = err.getvalue().strip().splitlines()[-1]
            print(f"| {name} | `bwdesign {shlex.join(argv)}` | {code} | {line} |")


# -- the same checks in Python -------------------------------------------------------


EXP = dict(a1=159827.5, a2=713.8, a3=222665.02, alpha=0.4795, beta=0.3762, gamma=0.0378)
P = preset("paper_experiment")
SINE = Sine(amplitude=80.0, offset=100.0, frequency=1.0)


def loop(dt=2e-4, controller=None):
    """The PHSO on the paper's gains with eq. (12) at lambda1 = 1, lambda2 = 2 1/s."""
    law = make_controller(P, 1.0, 2.0) if controller is None else controller
    return ClosedLoop(P, ObserverSpec.of("phso", (8, 64, -512)), law, dt=dt)


PYTHON = [
    ("a1 = 1e308", lambda: BoucWenParams(**{**EXP, "a1": 1e308}), ParameterError, r"\[1e-06"),
    (
        "a1 numpy bool",
        lambda: BoucWenParams(**{**EXP, "a1": np.bool_(True)}),
        ParameterError,
        "must be a number",
    ),  # fmt: skip
    ("a1 str", lambda: BoucWenParams(**{**EXP, "a1": "1e5"}), ParameterError, "must be a number"),
    (
        "udot_max 1e300",
        lambda: certify(P, (8, 64, -512), udot_max=np.float64(1e300)),
        InputError,
        "supported range",
    ),  # fmt: skip
    ("dt 1", lambda: certify(P, (8, 64, -512), udot_max=361, dt=1), InputError, "too long"),
    ("synthesize dt 1", lambda: synthesize(P, udot_max=361, dt=1.0), InputError, "too long"),
    (
        "ClosedLoop dt 1",
        lambda: simulate(loop(dt=1.0), SINE, duration=10.0),
        InputError,
        "too long",
    ),
    ("seed -3", lambda: simulate(loop(), SINE, duration=0.01, seed=-3), InputError, "seed = -3"),
    (
        "seed 3.0",
        lambda: simulate(loop(), SINE, duration=0.01, seed=3.0),
        InputError,
        "must be an integer",
    ),
    (
        "seed True",
        lambda: simulate(loop(), SINE, duration=0.01, seed=True),
        InputError,
        "must be an integer",
    ),
    ("amplitude 1e300", lambda: Sine(amplitude=1e300, frequency=1.0), ConfigError, "range"),
    (
        "ClosedLoop controller for another dt",
        lambda: loop(controller=make_controller(P, 1.0, 2.0, form="discrete", dt=1e-4)),
        InputError,
        r"built for dt = 0.0001 s, not 0.0002 s",
    ),
    (
        "ObserverSpec gains str",
        lambda: ObserverSpec.of("phso", ("8", 64, -512)),
        GainError,
        "must be a number",
    ),
    ("Start u_prev inf", lambda: Start(u_prev=np.inf), InputError, "u_prev must be finite"),
    ("gains str", lambda: certify(P, ("8", 64, -512), udot_max=361), ValueError, "numbers"),
    (
        "simulate above Nyquist",
        lambda: simulate(loop(), Sine(amplitude=1.0, frequency=3000.0), duration=0.01),
        InputError,
        r"Nyquist frequency 1/\(2 dt\) = 2500 Hz",
    ),
    (
        "simulate_batch above Nyquist",
        lambda: simulate_batch(
            loop(controller=TrackingController(P, 1.0, 2.0)),
            Sine(amplitude=1.0, frequency=2500.0),
            [P],
            duration=0.01,
        ),
        InputError,
        "at or above the Nyquist frequency",
    ),
    (
        "record dt 1e-16",
        lambda: IdentificationData.from_arrays(
            np.arange(400) * 1e-16, np.sin(np.arange(400.0)), np.cos(np.arange(400.0))
        ),
        InputError,
        r"dt \(s\) = 1e-16 is outside the supported range \[1e-09, 1\] s",
    ),
    (
        "UncertaintyBox.parse a1 twice",
        lambda: UncertaintyBox.parse("a1=2%,a1=3%"),
        InputError,
        "a1 given twice",
    ),
    ("UncertaintyBox zeta", lambda: UncertaintyBox({"zeta": ("rel", 0.1)}), InputError, "zeta"),
    (
        "UncertaintyBox.check leaving the class",
        lambda: UncertaintyBox.parse("beta=95%").check(P),
        ParameterError,
        "leaves the bounded class",
    ),
    (
        "excite below the smallest rate",
        lambda: design_excitation(P, umin=0.0, umax=120.0, udot_max=1e-6, duration=1.0, dt=1e-3),
        InputError,
        "below the smallest usable",
    ),
]


#: Issue 25: every number through bwdesign.validate, its range stated in the message.
RECORD = IdentificationData.from_arrays(
    np.arange(400) * 1e-3, 5 + 4 * np.sin(0.05 * np.arange(400.0)), np.cos(np.arange(400.0))
)
BOX = UncertaintyBox.from_dict({"a1": {"rel": 0.02}})
PYTHON += [
    (
        "UKF udot_max 1e300",
        lambda: UnscentedObserver(P, 2e-4, udot_max=1e300),
        InputError,
        r"udot_max \(V/s\) = 1e\+300 is outside the supported range \(0, 1e\+09\] V/s",
    ),
    (
        "observer dt 0",
        lambda: HysteresisObserver(P, (8, 64, -512), dt=0.0),
        InputError,
        r"dt \(s\) = 0 is outside",
    ),
    (
        "controller lambda1 1e300",
        lambda: TrackingController(P, 1e300, 2.0),
        GainError,
        r"lambda1 \(1/s\) = 1e\+300 is outside the supported range \(0, 1e\+12\] 1/s",
    ),
    (
        "excite duration -1",
        lambda: design_excitation(P, umin=0.0, umax=120.0, udot_max=1e3, duration=-1.0, dt=1e-3),
        InputError,
        r"duration \(s\) = -1 is outside the supported range \(0, inf\)",
    ),
    (
        "excite umin str",
        lambda: design_excitation(P, umin="0", umax=120.0, udot_max=1e3, duration=1.0, dt=1e-3),
        InputError,
        r"umin \(V\) must be a number, got str",
    ),
    (
        "identify multistart 0",
        lambda: identify(RECORD, multistart=0),
        InputError,
        "multistart = 0 is outside",
    ),
    (
        "identify multistart 2.0",
        lambda: identify(RECORD, multistart=2.0),
        InputError,
        "multistart must be an integer",
    ),
    (
        "digital_tuning mismatch 0.7",
        lambda: digital_tuning(P, 2e-4, mismatch=0.7),
        InputError,
        r"mismatch \(relative error\) = 0.7 is outside the supported range \[0, 0.5\)",
    ),
    (
        "digital_tuning margins.phase_deg nan",
        lambda: digital_tuning(P, 2e-4, margins=MarginRequirements(phase_deg=math.nan)),
        InputError,
        "margins.phase_deg deg must be finite",
    ),
    (
        "digital_tuning observer_radius str",
        lambda: digital_tuning(P, 2e-4, observer_radius="fast"),
        InputError,
        "observer_radius must be a number",
    ),
    (
        "RobustSearch max_candidates 0",
        lambda: RobustSearch(max_candidates=0),
        InputError,
        "max_candidates must be >= 1, got 0",
    ),
    (
        "synthesize_robust search dict",
        lambda: synthesize_robust(
            P,
            dt=2e-4,
            uncertainty=UncertaintyBox.parse("a1=2%"),
            udot_max=400.0,
            reference=Sine(amplitude=10.0, offset=10.0, frequency=1.0),
            search={"max_candidates": 2},
        ),
        InputError,
        "search must be a RobustSearch",
    ),
    (
        "simulate_zoh u_prev str",
        lambda: simulate_zoh(P, np.zeros(3), 2e-4, np.zeros(3), u_prev="0"),
        InputError,
        "u_prev must be a number, got str",
    ),
    (
        "certify_disturbance udot_max -1",
        lambda: certify_disturbance(P, (8, 64, -512, 100), udot_max=-1.0),
        InputError,
        r"udot_max \(V/s\) = -1 is outside the supported range \[0, 1e\+09\] V/s",
    ),
    (
        "robust observer noise_max nan",
        lambda: certify_robust_observer(
            P,
            (8, 64, -512),
            dt=2e-4,
            uncertainty=BOX,
            udot_max=361,
            input_range=(0, 120),
            noise_max=math.nan,
        ),
        InputError,
        "noise_max must be finite, got nan",
    ),  # fmt: skip
    (
        "robust observer interior_samples -1",
        lambda: certify_robust_observer(
            P,
            (8, 64, -512),
            dt=2e-4,
            uncertainty=BOX,
            udot_max=361,
            input_range=(0, 120),
            sampling=BoxSampling(-1),
        ),
        InputError,
        "interior_samples = -1 is outside",
    ),  # fmt: skip
    (
        "robust observer input_range str",
        lambda: certify_robust_observer(
            P,
            (8, 64, -512),
            dt=2e-4,
            uncertainty=BOX,
            udot_max=361,
            input_range=("0", 120),
        ),
        InputError,
        r"input_range u_lo \(V\) must be a number",
    ),  # fmt: skip
    (
        "Sine frequency 0",
        lambda: Sine(amplitude=1.0, frequency=0.0),
        ConfigError,
        "frequency = 0 is outside",
    ),
    (
        "requirements max_me_um -1",
        lambda: parse_requirements({"max_me_um": -1.0}),
        ConfigError,
        r"\[requirements\] max_me_um = -1 is outside the supported range \[0, inf\)",
    ),
    ("unknown extra", lambda: require("x", extra="nope", feature="f"), InputError, "unknown extra"),
]


@pytest.mark.parametrize("name, call, error, match", PYTHON, ids=[c[0] for c in PYTHON])
def test_python_entry_points(name, call, error, match):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(error, match=match):
            call()


def test_validate_semantics():
    assert real(np.float32(0.5), "x", within=DT) == 0.5
    assert real(np.int64(3), "x") == 3.0 and integer(np.uint8(7), "n", within=SEED) == 7
    for bad in (True, "1", None, [1.0], complex(1, 0)):
        with pytest.raises(InputError, match="must be a number"):
            real(bad, "x")
    for bad in (3.0, True, "3", np.float64(3)):
        with pytest.raises(InputError, match="must be an integer"):
            integer(bad, "n")
    with pytest.raises(InputError, match="must be finite"):
        real(float("nan"), "x")
    with pytest.raises(InputError, match=r"outside the supported range \[1e-09, 1\] s"):
        parse_real("2", "dt", within=DT)
    with pytest.raises(ParameterError) as info:
        real(-1.0, "owner: a2", within=DT, error=ParameterError)
    assert info.value.field == "a2"


# -- accepted as written: what spreadsheet programs and editors produce (issue 24) ----


def test_a_byte_order_mark_is_accepted(tmp_path):
    """A UTF-8 BOM at the start of a stage file or a CSV record reads as without it."""
    plain, bom = tmp_path / "plain.toml", tmp_path / "bom.toml"
    plain.write_text(GOOD_TOML)
    bom.write_bytes(b"\xef\xbb\xbf" + GOOD_TOML.encode())
    a, b = load_config(plain), load_config(bom)
    assert (a.plant, a.gains, a.dt, a.reference) == (b.plant, b.gains, b.dt, b.reference)
    _record()(tmp_path)
    text = (tmp_path / "rec.csv").read_text()
    (tmp_path / "bom.csv").write_text(text, encoding="utf-8-sig")
    assert (tmp_path / "bom.csv").read_bytes().startswith(b"\xef\xbb\xbft,u,y")
    x, y = load_data(tmp_path / "rec.csv"), load_data(tmp_path / "bom.csv")
    assert np.array_equal(x.u, y.u) and np.array_equal(x.y, y.y) and x.dt == y.dt


def test_simulate_batch_is_public_in_bwdesign_sim():
    import bwdesign.sim

    assert (
        "simulate_batch" in bwdesign.sim.__all__ and bwdesign.sim.simulate_batch is simulate_batch
    )
