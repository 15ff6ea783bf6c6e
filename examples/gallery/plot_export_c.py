"""
Firmware: ``export_c`` and its harness
======================================

``export_c`` writes the certified observers and the tracking law as C99 (``bw.h``,
``bw.c``: no heap, no I/O, only ``<math.h>``) with the certificate in the header's
comment block, plus ``harness.c``, a small program that reads ``u,z`` lines and prints
the observer's states with ``%.17g``. Compiling the harness on your toolchain and
diffing its output against ``HysteresisObserver.batch_filter`` is how to verify the
export on a target; in float64 the two agree bit for bit. The compile step runs only
where a C compiler (``cc``) is installed.
"""

import shutil
import subprocess
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from bwdesign import HysteresisObserver, export_c, load_config, simulate_zoh

stage = load_config("paper_experiment")
fw = Path(tempfile.mkdtemp(prefix="bwdesign-fw-")) / "fw"
out = export_c(stage, fw, precision="float64")
print(f"certified: {out.certified}; files: {', '.join(out.files)}")
header = (fw / "bw.h").read_text()
print(header[: header.index("*/") + 2])  # the certificate, as the header states it

# %%
# A record to replay: the stage's plant under a slow sine, with sensor noise
p, dt = stage.plant, stage.dt
t = np.arange(0.0, 0.5, dt)
u = 70 + 40 * np.sin(2 * np.pi * 2 * t)
z = simulate_zoh(p, u, dt, x0=np.zeros(3))[1:, 0]
z = z + 0.02 * np.random.default_rng(0).standard_normal(len(z))
python = HysteresisObserver(p, stage.gains, dt=dt).batch_filter(z, u)

cc = shutil.which("cc")
if cc is None:
    print("no C compiler (cc) here: the harness is written but not compiled")
else:
    sources = sorted(str(f) for f in fw.glob("*.c"))
    subprocess.run([cc, "-std=c99", "-O2", *sources, "-lm", "-o", str(fw / "harness")], check=True)
    lines = "".join(f"{a:.17g},{b:.17g}\n" for a, b in zip(u, z, strict=True))
    run = subprocess.run(
        [str(fw / "harness"), "phso"], input=lines, capture_output=True, text=True, check=True
    )
    c_states = np.loadtxt(run.stdout.splitlines(), delimiter=",")
    diff = np.abs(c_states - python)
    print(f"C harness vs Python batch_filter: max |difference| = {diff.max():.3g}")
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(t, python[:, 2], label="x3 estimate, Python")
    ax.plot(t, c_states[:, 2], "--", label="x3 estimate, C harness (float64)")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("x3 (um)")
    ax.legend()
    fig.tight_layout()

shutil.rmtree(fw.parent)  # the exported files were written to a temporary folder
