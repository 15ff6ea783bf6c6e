"""Safe outputs: no command destroys, moves or overwrites a file bwdesign did not write.

Every writer is pointed at targets the tests make themselves inside
``tmp_path`` (a directory holding a user's file, a plain file, a FIFO from
``os.mkfifo``, a symlink, a read-only file, ``.`` and ``""``); never at system
paths. The report writer runs in-process with a fast stand-in for the
computation (the writing is what is under test), except in the SIGKILL test,
which runs the real ``bwdesign report`` in a subprocess.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import bwdesign.output.files.directory as directory
import bwdesign.output.files.staging as files_staging
import bwdesign.report.certified as certified
from bwdesign.cli.main import main
from bwdesign.errors import ConfigError, OutputError
from bwdesign.output.files import MANIFEST, prepare_directory, prepare_file
from bwdesign.report.document import Document

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "paper_experiment.toml"
USER_BYTES = b"my notes \xe2\x80\x94 do not lose\n"
SIM = [
    "simulate", "--plant", "paper_experiment", "--gains", "8,64,-512", "--amplitude", "80",
    "--offset", "100", "--frequency", "1", "--lambda1", "1", "--lambda2", "2", "--dt", "2e-4",
    "--duration", "0.01",
]  # fmt: skip


def _fake_build(
    config,
    out,
    *,
    allow_unbounded=False,
    quiet=False,
    date=None,
    out_dir=None,
    cache=None,
    workers=1,
):
    """Stand-in for the report's study and rendering: a figure, a document, a verdict."""
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    (figs / "a.png").write_bytes(b"\x89PNG fake")
    doc = Document("fake report")
    doc.para("fake")
    verdict = SimpleNamespace(ok=True, text="CERTIFIED (fake)")
    return doc, SimpleNamespace(to_dict=lambda: {"fake": True}, verdict=verdict)


@pytest.fixture
def fast_report(monkeypatch):
    monkeypatch.setattr(certified, "build_report", _fake_build)


def report(out, *extra):
    return main(["report", "--config", str(CONFIG), "--out", str(out), "--quiet", *extra])


def snapshot(path: Path) -> dict[str, bytes | str]:
    """Every entry below ``path`` (hidden ones included): bytes of files, kinds of others."""
    out: dict[str, bytes | str] = {}
    for p in sorted(path.rglob("*")):
        st = os.lstat(p)
        rel = p.relative_to(path).as_posix()
        out[rel] = p.read_bytes() if stat.S_ISREG(st.st_mode) else stat.filemode(st.st_mode)[0]
    return out


def assert_one_error(capsys, *needles):
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert lines and lines[-1].startswith("error: "), err
    assert len([ln for ln in lines if ln.startswith("error: ")]) == 1
    assert "Traceback" not in err and "Warning" not in err
    for n in needles:
        assert n in lines[-1], lines[-1]
    return lines[-1]


def no_debris(path: Path) -> None:
    hidden = [p for p in path.rglob(".*") if p.name != MANIFEST]
    assert not hidden, hidden


# -- report --out DIR ------------------------------------------------------------


def test_report_refuses_a_directory_holding_a_users_file(tmp_path, fast_report, capsys):
    out = tmp_path / "mydir"
    out.mkdir()
    (out / "notes.txt").write_bytes(USER_BYTES)
    before = snapshot(tmp_path)
    assert report(out) == 2
    assert_one_error(capsys, "notes.txt", "--force")
    assert snapshot(tmp_path) == before


def test_report_force_writes_beside_the_users_file(tmp_path, fast_report, capsys):
    out = tmp_path / "mydir"
    out.mkdir()
    (out / "notes.txt").write_bytes(USER_BYTES)
    assert report(out, "--force") == 0
    assert (out / "notes.txt").read_bytes() == USER_BYTES
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["command"] == "report" and manifest["complete"] is True
    assert set(manifest["files"]) == {
        "report.md",
        "report.html",
        "certificate.json",
        "figures/a.png",
    }
    # the next run replaces its own files, again with --force, and keeps the user's
    assert report(out, "--force") == 0
    assert (out / "notes.txt").read_bytes() == USER_BYTES
    no_debris(tmp_path)


def test_report_force_never_overwrites_a_foreign_file(tmp_path, fast_report, capsys):
    out = tmp_path / "mydir"
    out.mkdir()
    (out / "report.md").write_bytes(USER_BYTES)
    before = snapshot(tmp_path)
    assert report(out, "--force") == 2
    assert_one_error(capsys, "report.md")
    assert snapshot(tmp_path) == before


def test_report_force_refuses_a_foreign_file_found_only_at_the_commit(tmp_path, fast_report):
    out = tmp_path / "mydir"
    out.mkdir()
    (out / "figures").mkdir()
    (out / "figures" / "a.png").write_bytes(USER_BYTES)  # not in REPORT_FILES: seen at commit
    before = snapshot(tmp_path)
    assert report(out, "--force") == 2
    assert snapshot(tmp_path) == before


def test_report_replaces_its_own_report_and_drops_obsolete_files(tmp_path, fast_report):
    out = tmp_path / "rep"
    with prepare_directory(out, command="report").stage() as st:
        st.write_text("report.md", "old")
        st.write_text("figures/old.png", "old figure")
    assert report(out) == 0
    assert (out / "report.md").read_text() != "old"
    assert not (out / "figures" / "old.png").exists()
    assert (out / "figures" / "a.png").exists()
    no_debris(tmp_path)


def test_report_refuses_a_changed_own_file_unless_forced(tmp_path, fast_report, capsys):
    out = tmp_path / "rep"
    assert report(out) == 0
    (out / "report.md").write_text("edited by hand")
    assert report(out) == 2
    assert_one_error(capsys, "report.md", "changed since")
    assert (out / "report.md").read_text() == "edited by hand"
    assert report(out, "--force") == 0  # a listed file: --force may replace it
    assert (out / "report.md").read_text() != "edited by hand"


def test_report_refuses_a_plain_file(tmp_path, fast_report, capsys):
    afile = tmp_path / "afile"
    afile.write_bytes(USER_BYTES)
    for extra in ((), ("--force",)):
        assert report(afile, *extra) == 2
        assert_one_error(capsys, "not a directory")
        assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]
        assert afile.read_bytes() == USER_BYTES


@pytest.mark.parametrize("kind", ["symlink", "fifo", "symlink-to-file"])
def test_report_refuses_links_and_fifos(tmp_path, fast_report, capsys, kind):
    real = tmp_path / "real"
    real.mkdir()
    (real / "notes.txt").write_bytes(USER_BYTES)
    out = tmp_path / "out"
    if kind == "symlink":
        out.symlink_to(real, target_is_directory=True)
    elif kind == "symlink-to-file":
        out.symlink_to(real / "notes.txt")
    else:
        os.mkfifo(out)
    before = snapshot(tmp_path)
    assert report(out, "--force") == 2
    assert_one_error(capsys, "symbolic link" if kind.startswith("symlink") else "FIFO")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("where", [".", ""])
def test_report_refuses_the_current_directory_and_the_empty_path(
    tmp_path, fast_report, capsys, monkeypatch, where
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_bytes(USER_BYTES)
    before = snapshot(tmp_path)
    assert report(where, "--force") == 2
    assert_one_error(capsys, "current directory" if where else "empty path")
    assert snapshot(tmp_path) == before


def test_report_refuses_read_only_targets(tmp_path, fast_report, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    locked = tmp_path / "locked"
    locked.mkdir()
    try:
        ro.chmod(0o555)
        locked.chmod(0o555)
        assert report(ro) == 2
        assert_one_error(capsys, "not writable")
        assert report(locked / "new") == 2  # the parent cannot be written
        assert_one_error(capsys, "not writable")
        assert list(ro.iterdir()) == [] and list(locked.iterdir()) == []
    finally:
        ro.chmod(0o755)
        locked.chmod(0o755)


def test_report_refuses_another_commands_directory(tmp_path, fast_report, capsys):
    out = tmp_path / "stage"
    with prepare_directory(out, command="identify").stage() as st:
        st.write_text("stage.toml", "[plant]\n")
    before = snapshot(tmp_path)
    assert report(out, "--force") == 2
    assert_one_error(capsys, "bwdesign identify")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize(
    "manifest",
    ['{"files": {"notes.txt": []}}', "[1, 2]", "not json", b"\xff\xfe", '{"written_by": 3}'],
)
def test_report_refuses_a_foreign_manifest(tmp_path, fast_report, capsys, manifest):
    out = tmp_path / "rep"
    out.mkdir()
    data = manifest if isinstance(manifest, bytes) else manifest.encode()
    (out / MANIFEST).write_bytes(data)
    (out / "notes.txt").write_bytes(USER_BYTES)
    before = snapshot(tmp_path)
    assert report(out, "--force") == 2
    assert_one_error(capsys, "not a bwdesign manifest")
    assert snapshot(tmp_path) == before


def test_failed_run_leaves_no_directory_and_no_debris(tmp_path, monkeypatch, capsys):
    def boom(*a, **k):
        raise ConfigError("the computation failed")

    monkeypatch.setattr(certified, "build_report", boom)
    assert report(tmp_path / "deep" / "new") == 2
    assert_one_error(capsys, "the computation failed")
    assert list(tmp_path.iterdir()) == []


def test_disk_full_at_write_time_is_one_error_line(tmp_path, fast_report, monkeypatch, capsys):
    out = tmp_path / "rep"
    assert report(out) == 0
    before = snapshot(tmp_path)
    real_write = directory.write_new

    def full(path, data):
        if path.name == "report.md":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real_write(path, data)

    monkeypatch.setattr(directory, "write_new", full)
    assert report(out) == 2
    assert_one_error(capsys, "No space left on device")
    assert snapshot(tmp_path) == before


def test_files_get_the_users_umask(tmp_path, fast_report):
    old = os.umask(0o027)
    try:
        assert report(tmp_path / "rep") == 0
        assert main([*SIM, "--csv", str(tmp_path / "run.csv")]) == 0
    finally:
        os.umask(old)
    for p in [tmp_path / "rep" / "report.md", tmp_path / "rep" / MANIFEST, tmp_path / "run.csv"]:
        assert stat.S_IMODE(p.stat().st_mode) == 0o640, p
    assert stat.S_IMODE((tmp_path / "rep" / "figures").stat().st_mode) == 0o750


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


@pytest.fixture
def owner_pid():
    """``pid("dead")``: a pid no process has; ``pid("alive")``: a sleeping child's."""
    children = []

    def pid(state):
        if state == "dead":
            return _dead_pid()
        children.append(subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]))
        return children[-1].pid

    yield pid
    for child in children:
        child.kill()
        child.wait()


#: (host, pid, age in hours, removed by the next run): this host, another host sharing
#: the folder, and a name from before hosts were recorded (None)
OWNERS = [
    ("this", "dead", 0, True),  # a killed run here
    ("this", "alive", 0, False),  # a run here still writing
    ("other", "dead", 0, False),  # another host's run: a pid says nothing here
    ("other", "alive", 25, True),  # ... until nothing changed it for 24 h
    (None, "dead", 0, False),
    (None, "dead", 25, True),
]


def _owned(host, pid):
    here = files_staging.this_host()
    return f"{pid}@{here}" if host == "this" else f"{pid}@other-host.lan" if host else f"{pid}"


@pytest.mark.parametrize("host, state, hours, removed", OWNERS)
def test_staging_is_removed_only_when_its_run_is_gone(
    tmp_path, fast_report, capsys, owner_pid, host, state, hours, removed
):
    out = tmp_path / "rep"
    assert report(out) == 0
    staging = out / f".bwdesign-tmp-report-{_owned(host, owner_pid(state))}-deadbeef"
    (staging / "figures").mkdir(parents=True)
    (staging / "figures" / "half.png").write_bytes(b"half")
    old = time.time() - hours * 3600
    os.utime(staging, (old, old))
    capsys.readouterr()
    if removed:
        assert report(out) == 0
        no_debris(tmp_path)
    else:
        assert report(out) == 2
        who = {"this": files_staging.this_host(), "other": "other-host.lan"}.get(host)
        assert_one_error(capsys, staging.name, who or "unrecorded host", "24 h")
        assert (staging / "figures" / "half.png").read_bytes() == b"half"


@pytest.fixture
def listed(monkeypatch):
    """The directories the output layer lists (``os.listdir``), in order."""
    seen = []
    real = os.listdir

    def spy(path="."):
        seen.append(os.path.abspath(path))
        return real(path)

    monkeypatch.setattr(os, "listdir", spy)
    return seen


def test_only_the_top_level_and_the_manifests_own_directories_are_listed(tmp_path, listed):
    out = tmp_path / "rep"
    with prepare_directory(out, command="report").stage() as st:
        st.write_text("figures/a.png", "ours")
    (out / "big" / "deep" / "deeper").mkdir(parents=True)
    (out / "big" / "deep" / "deeper" / "x.txt").write_bytes(USER_BYTES)
    (out / "figures" / "sub").mkdir()  # inside a directory the manifest names
    listed.clear()
    with pytest.raises(OutputError, match=r"holds big/ \(and 1 more\)"):
        prepare_directory(out, command="report")
    assert listed == [str(out), str(out / "figures")]  # big/ and figures/sub/ not entered
    (out / "big" / "deep" / "deeper" / "x.txt").unlink()
    for d in ("big/deep/deeper", "big/deep", "big"):
        (out / d).rmdir()
    with pytest.raises(OutputError, match=r"holds figures/sub/, which"):
        prepare_directory(out, command="report")


def test_the_filesystem_root_is_refused_from_its_top_level(listed):
    """``export-c --out /`` walked the whole filesystem (a /proc/.../fd traceback)."""
    with pytest.raises(OutputError):
        prepare_directory("/", command="export-c", what="--out")
    assert set(listed) <= {"/"}  # read only: / holds no bwdesign staging to clear


def test_entries_vanishing_during_the_scan_are_gone(tmp_path, monkeypatch):
    """Another process's temporary file, or a listed file, deleted while bwdesign looks."""
    out = tmp_path / "rep"
    with prepare_directory(out, command="report").stage() as st:
        st.write_text("report.md", "ours")
    (out / "tmp.swp").write_bytes(b"editor swap file")
    real_lstat, real_hash = os.lstat, directory.sha256_of

    def vanishing_lstat(path, *a, **k):
        if Path(path).name == "tmp.swp":
            os.unlink(path)  # deleted between the listing and the look
        return real_lstat(path, *a, **k)

    def vanishing_hash(path):
        os.unlink(path)
        return real_hash(path)

    monkeypatch.setattr(os, "lstat", vanishing_lstat)
    monkeypatch.setattr(directory, "sha256_of", vanishing_hash)
    target = prepare_directory(out, command="report")  # not foreign, not an error
    assert target.previous == {}  # report.md vanished too: nothing to replace


def test_kill_during_the_commit_leaves_a_directory_the_next_run_replaces(tmp_path):
    """A child process dies (os._exit) after moving one file of three into place."""
    out = tmp_path / "rep"
    with prepare_directory(out, command="report").stage() as st:
        for name in ("a.txt", "b.txt", "c.txt"):
            st.write_text(name, f"old {name}")
    pid = os.fork()
    if pid == 0:  # pragma: no cover - runs in the child
        moves = []
        real_replace = os.replace

        def dying_replace(src, dst):
            if Path(dst).name != MANIFEST:
                moves.append(dst)
                if len(moves) == 2:
                    os._exit(9)
            real_replace(src, dst)

        os.replace = dying_replace
        with prepare_directory(out, command="report").stage() as st:
            for name in ("a.txt", "b.txt", "c.txt"):
                st.write_text(name, f"new {name}")
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    assert os.WEXITSTATUS(status) == 9
    texts = sorted((out / n).read_text() for n in ("a.txt", "b.txt", "c.txt"))
    assert texts == ["new a.txt", "old b.txt", "old c.txt"]
    assert json.loads((out / MANIFEST).read_text())["complete"] is False
    target = prepare_directory(out, command="report")  # no --force needed: all recognised
    with target.stage() as st:
        for name in ("a.txt", "b.txt", "c.txt"):
            st.write_text(name, f"next {name}")
    assert all((out / n).read_text() == f"next {n}" for n in ("a.txt", "b.txt", "c.txt"))
    assert json.loads((out / MANIFEST).read_text())["complete"] is True
    no_debris(tmp_path)


@pytest.mark.slow
def test_sigkill_mid_report_keeps_the_old_report(tmp_path):
    """The real ``bwdesign report`` killed while it writes figures: old report whole."""
    out = tmp_path / "rep"
    with prepare_directory(out, command="report").stage() as st:
        st.write_text("report.md", "previous report")
        st.write_text("certificate.json", "{}")
    before = snapshot(out)
    cmd = [sys.executable, "-m", "bwdesign", "report", "--config", str(CONFIG), "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 600  # a loaded machine: it polls, so it waits only as needed
    figure = None
    while time.monotonic() < deadline and figure is None:
        figure = next(iter(out.glob(".bwdesign-tmp-report-*/figures/*.png")), None)
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert figure is not None, "the report never started writing"
    assert proc.returncode == -signal.SIGKILL
    after = snapshot(out)
    assert {k: v for k, v in after.items() if not k.startswith(".bwdesign-tmp-")} == before
    r = subprocess.run([*cmd, "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and "Warning" not in r.stderr
    assert (out / "report.md").read_text().startswith("# Certified-gains report")
    no_debris(tmp_path)


# -- simulate --csv FILE ------------------------------------------------------------


def simulate_csv(path, *extra):
    return main([*SIM, "--csv", str(path), *extra])


def test_csv_is_written_signed_and_rewritten(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    assert simulate_csv(csv) == 0
    lines = csv.read_text().splitlines()
    assert lines[0].startswith("# written by bwdesign ") and "(simulate --csv) sha256=" in lines[0]
    assert lines[1] == "t,x1,x2,x3,x1hat,x2hat,x3hat,u,x_d,e,z"
    assert np.loadtxt(csv, delimiter=",", skiprows=2).shape == (50, 11)
    assert simulate_csv(csv) == 0  # its own file: replaced
    no_debris(tmp_path)


def test_csv_refuses_a_users_file(tmp_path, capsys):
    csv = tmp_path / "data.csv"
    csv.write_bytes(USER_BYTES)
    assert simulate_csv(csv) == 2
    assert_one_error(capsys, "never overwrites")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.csv"]
    assert csv.read_bytes() == USER_BYTES


def test_csv_refuses_an_edited_bwdesign_file(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    assert simulate_csv(csv) == 0
    with open(csv, "a") as f:
        f.write("# my annotation\n")
    edited = csv.read_bytes()
    capsys.readouterr()
    assert simulate_csv(csv) == 2
    assert_one_error(capsys, "changed since")
    assert csv.read_bytes() == edited


def test_csv_refuses_a_directory_holding_a_users_file(tmp_path, capsys):
    d = tmp_path / "mydir"
    d.mkdir()
    (d / "notes.txt").write_bytes(USER_BYTES)
    before = snapshot(tmp_path)
    for target in (d, str(d) + "/"):
        assert simulate_csv(target) == 2
        assert_one_error(capsys, "directory")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("kind", ["symlink", "dangling symlink", "fifo", "read-only"])
def test_csv_refuses_non_regular_and_read_only_targets(tmp_path, capsys, kind):
    real = tmp_path / "real.csv"
    target = tmp_path / "out.csv"
    if kind == "symlink":
        assert simulate_csv(real) == 0
        capsys.readouterr()
        target.symlink_to(real)
    elif kind == "dangling symlink":
        target.symlink_to(tmp_path / "nowhere.csv")
    elif kind == "fifo":
        os.mkfifo(target)
    else:
        assert simulate_csv(target) == 0  # even its own file, once made read-only
        capsys.readouterr()
        target.chmod(0o444)
    before = snapshot(tmp_path)
    assert simulate_csv(target) == 2
    message = {"fifo": "FIFO", "read-only": "read-only"}.get(kind, "symbolic link")
    assert_one_error(capsys, message)
    assert snapshot(tmp_path) == before


def test_csv_refuses_empty_path_and_missing_or_locked_parent(tmp_path, capsys):
    assert simulate_csv("") == 2
    assert_one_error(capsys, "empty path")
    assert simulate_csv(tmp_path / "absent" / "x.csv") == 2
    assert_one_error(capsys, "does not exist")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        assert simulate_csv(locked / "x.csv") == 2
        assert_one_error(capsys, "not writable")
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o755)


@pytest.mark.parametrize("host, state, hours, removed", OWNERS)
def test_csv_temporary_is_removed_only_when_its_run_is_gone(
    tmp_path, owner_pid, host, state, hours, removed
):
    csv = tmp_path / "run.csv"
    stale = tmp_path / f".run.csv.bwdesign-tmp-{_owned(host, owner_pid(state))}-cafe0123"
    stale.write_text("half a csv")
    old = time.time() - hours * 3600
    os.utime(stale, (old, old))
    assert simulate_csv(csv) == 0
    assert stale.exists() is not removed
    stale.unlink(missing_ok=True)
    no_debris(tmp_path)


def test_csv_failure_while_writing_keeps_the_previous_file(tmp_path, monkeypatch, capsys):
    csv = tmp_path / "run.csv"
    assert simulate_csv(csv) == 0
    before = snapshot(tmp_path)

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savetxt", full)
    capsys.readouterr()
    assert simulate_csv(csv) == 2
    assert_one_error(capsys, "No space left on device")
    assert snapshot(tmp_path) == before


# -- the layer's Python API ------------------------------------------------------------


def test_stage_paths_stay_inside(tmp_path):
    with prepare_directory(tmp_path / "o", command="t").stage() as st:
        for bad in ("../x", "/abs", ""):
            with pytest.raises(ValueError):
                st.file(bad)
        st.write_text("ok.txt", "ok")
    assert (tmp_path / "o" / "ok.txt").read_text() == "ok"


def test_file_without_comment_syntax_is_never_replaced(tmp_path):
    target = prepare_file(tmp_path / "x.json", command="t", comment=None)
    target.write_text("{}")
    assert (tmp_path / "x.json").read_text() == "{}"
    with pytest.raises(OutputError, match="never overwrites"):
        prepare_file(tmp_path / "x.json", command="t", comment=None)


@pytest.mark.parametrize("swallowed", [False, True])
def test_interrupt_mid_report_keeps_the_previous_report(tmp_path, monkeypatch, capsys, swallowed):
    """Ctrl-C while computing: exit 130, previous report whole, no debris; also when a
    library caught the KeyboardInterrupt (the handler recorded it: nothing is committed)."""
    out = tmp_path / "rep"
    monkeypatch.setattr(certified, "build_report", _fake_build)
    assert report(out) == 0
    before = snapshot(tmp_path)

    def interrupted(config, out, **kw):
        result = _fake_build(config, out, **kw)
        (out / "figures" / "b.png").write_bytes(b"\x89PNG new")  # a commit would show
        try:
            signal.raise_signal(signal.SIGINT)  # what Ctrl-C does, through main's handler
        except KeyboardInterrupt:
            if not swallowed:
                raise
        return result

    monkeypatch.setattr(certified, "build_report", interrupted)
    capsys.readouterr()
    assert report(out) == 130
    assert_one_error(capsys, "interrupted")
    assert snapshot(tmp_path) == before


# -- the directory rules as a property ------------------------------------------------


NAMES = ["report.md", "a.txt", "figures/a.png", "figures/b.png", "sub/deep/c.txt", "notes.txt"]


@settings(max_examples=30, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    ours=st.lists(st.sampled_from(NAMES), unique=True, max_size=4),
    foreign=st.lists(
        st.tuples(
            st.sampled_from([*NAMES, "figures/user.png", "empty/"]),
            st.sampled_from(["file", "fifo", "symlink"]),
        ),
        max_size=3,
    ),  # fmt: skip
    edit=st.booleans(),
    new=st.lists(st.sampled_from(NAMES), unique=True, min_size=1, max_size=4),
    force=st.booleans(),
)
def test_directory_rules_hold_for_any_tree(tmp_path_factory, ours, foreign, edit, new, force):
    base = tmp_path_factory.mktemp("tree")
    out = base / "out"
    if ours:
        with prepare_directory(out, command="report").stage() as st_:
            for rel in ours:
                st_.write_text(rel, f"old {rel}")
    out.mkdir(exist_ok=True)
    placed = []
    for rel, kind in foreign:
        p = out / rel.rstrip("/")
        if (
            rel in ours
            or os.path.lexists(p)
            or any(
                os.path.lexists(out / parent) and not (out / parent).is_dir()
                for parent in Path(rel).parents
            )
        ):
            continue
        if rel.endswith("/"):
            p.mkdir(parents=True)
        else:
            p.parent.mkdir(parents=True, exist_ok=True)
            if kind == "file":
                p.write_bytes(USER_BYTES)
            elif kind == "fifo":
                os.mkfifo(p)
            else:
                p.symlink_to(base)
        placed.append(rel.rstrip("/"))
    if edit and ours:
        (out / ours[0]).write_text("edited by the user")
        placed.append(ours[0])
    foreign_before = {k: v for k, v in snapshot(out).items() if k in placed}
    before = snapshot(base)
    try:
        target = prepare_directory(out, command="report", force=force)
        with target.stage() as st_:
            for rel in new:
                st_.write_text(rel, f"new {rel}")
    except OutputError:
        assert snapshot(base) == before  # refused: nothing changed at all
        return
    assert force or not placed  # without --force only a clean directory is written
    after = snapshot(out)
    for rel, value in foreign_before.items():
        if rel in new and edit and rel == ours[0]:
            continue  # a listed file the user edited: --force replaces it
        assert after[rel] == value, rel  # foreign entries untouched
    for rel in new:
        assert (out / rel).read_text() == f"new {rel}"
    manifest = json.loads((out / MANIFEST).read_text())
    assert set(manifest["files"]) == set(new) and manifest["complete"] is True
    for rel in set(ours) - set(new) - set(placed):
        assert not (out / rel).exists(), rel  # bwdesign's own obsolete files go
    assert not list(out.rglob(".bwdesign-tmp-*"))
