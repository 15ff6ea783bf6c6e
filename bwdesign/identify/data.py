"""Measured records for identification: (t, u, y) arrays, CSV and NPZ loading, checks.

Units: t in s, u in V, y in µm (the package's length unit). Convert before
loading: a logger in mm gives ``y_um = 1000 y_mm``; one in nm gives
``y_um = y_nm / 1000``; a logged amplifier output in kV gives ``u_V = 1000 u_kV``.

Sample convention (docs/design.md, section "The sample clock"): ``u[k]`` is the command held over
``[t_k, t_k + dt)`` and ``y[k]`` the displacement at the end of that interval.
A logger that stamps ``y`` at the start of the interval is a one-sample delay,
which :func:`bwdesign.identify` estimates.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..validate import DT, SIGNAL, real

__all__ = ["IdentificationData", "load_data", "MIN_SAMPLES", "DT_TOLERANCE"]

#: Fewest samples a record may have (the fit has up to 11 unknowns).
MIN_SAMPLES = 200
#: Largest allowed deviation of a time step from the median step, relative to it.
DT_TOLERANCE = 1e-3


@dataclass(frozen=True, eq=False)
class IdentificationData:
    """One validated experiment record.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times (s), uniform and increasing.
    u : ndarray, shape (N,)
        Held input (V).
    y : ndarray, shape (N,)
        Measured displacement at the end of each sample (µm).
    dt : float
        Sample time (s): the mean step, rounded to 12 significant digits.
    source : str
        Where the record came from (a path, or a description).
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    dt: float
    source: str = ""

    @classmethod
    def from_arrays(cls, t, u, y, *, source: str = "") -> IdentificationData:
        """Validate and wrap three equal-length arrays.

        Raises
        ------
        InputError
            Shapes differ, a value is NaN or infinite (the first bad row is
            named), ``t`` is not increasing, has a gap (a step over 1.5 times the
            median; the rows and the missing samples are named) or is not uniform
            within :data:`DT_TOLERANCE`, fewer than :data:`MIN_SAMPLES` samples, ``u``
            or ``y`` outside :data:`bwdesign.validate.SIGNAL`, the sample time
            outside :data:`bwdesign.validate.DT` (the range every command takes),
            or the input or the output never moves.
        """
        where = f"{source}: " if source else ""
        arrays = {}
        for name, a in (("t", t), ("u", u), ("y", y)):
            try:
                a = np.asarray(a, dtype=float)
            except (TypeError, ValueError):
                raise InputError(f"{where}column {name} is not numeric") from None
            if a.ndim != 1:
                raise InputError(f"{where}column {name} must be 1-D, got shape {a.shape}")
            arrays[name] = a
        t, u, y = arrays["t"], arrays["u"], arrays["y"]
        if not (t.size == u.size == y.size):
            raise InputError(
                f"{where}columns t, u, y have different lengths ({t.size}, {u.size}, {y.size})"
            )
        bad = ~(np.isfinite(t) & np.isfinite(u) & np.isfinite(y))
        if bad.any():
            rows = np.flatnonzero(bad)
            raise InputError(
                f"{where}{rows.size} row(s) with NaN or infinite values, first at data row "
                f"{rows[0] + 1}; remove or repair them (a gap breaks the sample clock)"
            )
        if t.size < MIN_SAMPLES:
            raise InputError(
                f"{where}{t.size} samples; identification needs at least {MIN_SAMPLES}"
            )
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.flatnonzero(steps <= 0)[0])
            raise InputError(
                f"{where}t is not increasing at data row {k + 2} "
                f"(t = {t[k + 1]:.9g} s after {t[k]:.9g} s)"
            )
        dt = float(np.median(steps))
        # the range every other command takes for dt: the stage file written from it must load
        real(dt, f"{where}the record's sample time dt (s)", within=DT)
        dev = np.abs(steps - dt) / dt
        if steps.max() > 1.5 * dt:
            k = int(np.argmax(steps))
            missing = int(round(steps[k] / dt)) - 1
            raise InputError(
                f"{where}a gap in t between data rows {k + 1} and {k + 2}: t jumps from "
                f"{t[k]:.9g} s to {t[k + 1]:.9g} s ({steps[k]:.6g} s, about {missing} missing "
                f"sample(s) at the median step {dt:.6g} s); identification needs an unbroken "
                "record: split it at the gap or fill it"
            )
        if dev.max() > DT_TOLERANCE:
            k = int(np.argmax(dev))
            raise InputError(
                f"{where}t is not uniformly sampled: step {steps[k]:.6g} s at data row {k + 2} "
                f"differs from the median step {dt:.6g} s by {100 * dev[k]:.3g} % "
                f"(tolerance {100 * DT_TOLERANCE:g} %)"
            )
        for name, a, unit in (("u", u, "V"), ("y", y, "µm")):
            k = int(np.argmax(np.abs(a)))
            real(float(a[k]), f"{where}{name} at data row {k + 1} ({unit})", within=SIGNAL)
        if np.ptp(u) <= 1e-12 * max(1.0, float(np.max(np.abs(u)))):
            raise InputError(
                f"{where}the input u never moves (constant {u[0]:g} V): nothing to fit"
            )
        if np.ptp(y) <= 1e-12 * max(1.0, float(np.max(np.abs(y)))):
            raise InputError(f"{where}the output y never moves (constant {y[0]:g} µm)")
        for a in (t, u, y):
            a.setflags(write=False)
        # the mean step over the record, to 12 digits (a logged 2e-4 stays 2e-4)
        dt = float(f"{(t[-1] - t[0]) / (t.size - 1):.12g}")
        real(dt, f"{where}the record's sample time dt (s)", within=DT)
        return cls(t=t, u=u, y=y, dt=dt, source=source)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)


def _parse_columns(columns: str | tuple[str, str, str] | None) -> tuple[str, str, str]:
    if columns is None:
        return ("t", "u", "y")
    if isinstance(columns, str):
        columns = tuple(c.strip() for c in columns.split(","))
    if len(columns) != 3 or not all(columns):
        raise InputError(f"columns must name three columns T,U,Y, got {columns!r}")
    return tuple(columns)  # type: ignore[return-value]


def load_data(
    path: str | Path, *, columns: str | tuple[str, str, str] | None = None
) -> IdentificationData:
    """Read a record from CSV (header row; ``#`` comment lines skipped) or NPZ.

    Parameters
    ----------
    path : str or Path
        ``.csv`` (or any text file with a header row) or ``.npz``.
    columns : str or tuple of 3 str, optional
        Names of the time, input and output columns (``"t,u,y"`` by default);
        other columns are ignored.

    A UTF-8 byte-order mark at the start of a CSV file is accepted.

    Raises
    ------
    InputError
        Missing file or column, a directory, non-numeric value (row and column
        named), and every check of :meth:`IdentificationData.from_arrays`.
    """
    path = Path(path)
    names = _parse_columns(columns)
    if path.is_dir():
        raise InputError(f"data file {str(path)!r} is a directory; give a .csv or .npz file")
    if not path.exists():
        raise InputError(f"data file {str(path)!r} does not exist")
    if not path.is_file():
        raise InputError(f"data file {str(path)!r} is not a regular file")
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as npz:
                missing = [c for c in names if c not in npz.files]
                if missing:
                    raise InputError(
                        f"{path}: missing array(s) {', '.join(missing)}; the file has "
                        f"{', '.join(npz.files) or 'none'} (map names with --columns T,U,Y)"
                    )
                arrays = [np.array(npz[c]) for c in names]
        except (OSError, ValueError) as err:
            raise InputError(f"{path}: not a readable .npz file ({err})") from None
        for c, a in zip(names, arrays, strict=True):
            if not np.issubdtype(a.dtype, np.number):
                raise InputError(f"{path}: array {c} is not numeric (dtype {a.dtype})")
        return IdentificationData.from_arrays(*arrays, source=str(path))
    try:
        # utf-8-sig: a byte-order mark (spreadsheet programs write one) is not a header character
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"cannot read data file {str(path)!r}: {err}") from None
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip()]
    lines = [(i, ln) for i, ln in lines if not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"{path}: no header row and no data")
    rows = list(csv.reader([ln for _, ln in lines]))
    header = [h.strip() for h in rows[0]]
    missing = [c for c in names if c not in header]
    if missing:
        raise InputError(
            f"{path}: missing column(s) {', '.join(missing)}; the header has "
            f"{', '.join(header)} (map names with --columns T,U,Y)"
        )
    idx = [header.index(c) for c in names]
    out = np.empty((len(rows) - 1, 3))
    for r, row in enumerate(rows[1:]):
        for j, (c, i) in enumerate(zip(names, idx, strict=True)):
            try:
                out[r, j] = float(row[i])
            except IndexError:
                raise InputError(
                    f"{path}: line {lines[r + 1][0]} has no value for column {c}"
                ) from None
            except ValueError:
                raise InputError(
                    f"{path}: non-numeric value {row[i].strip()!r} in column {c} at line "
                    f"{lines[r + 1][0]}"
                ) from None
    if out.shape[0] == 0:
        raise InputError(f"{path}: header row but no data")
    return IdentificationData.from_arrays(out[:, 0], out[:, 1], out[:, 2], source=str(path))
