"""Log-axis tick labels drawn in plain Unicode text, not mathtext."""

import io

import numpy as np

from bwdesign.plotting.figures import save_figure
from bwdesign.plotting.styles import new_figure, plain_tick_label


def test_plain_tick_label_forms():
    assert plain_tick_label(r"$\mathdefault{10^{-3}}$") == "10\u207b\u00b3"
    assert plain_tick_label(r"$\mathdefault{2\times10^{3}}$") == "2\u00d710\u00b3"
    assert plain_tick_label(r"$\mathdefault{-1}$") == "\u22121"
    assert plain_tick_label(r"$\alpha$") == r"$\alpha$"  # other markup: unchanged
    assert plain_tick_label("abc") == "abc"


def test_log_axes_have_no_mathtext_labels():
    fig, axes = new_figure(1, 2, figsize=(4, 2))
    axes[0, 0].semilogy(np.arange(1, 5), [1e-3, 1e-1, 1e1, 1e3])
    axes[0, 1].plot([-100, 100], [0, 1])
    axes[0, 1].set_xscale("symlog", linthresh=1.0)
    save_figure(fig, io.BytesIO(), dpi=50)
    labels = [t.get_text() for ax in fig.axes for t in ax.get_yticklabels() + ax.get_xticklabels()]
    assert any("\u00b3" in s for s in labels)
    assert not [s for s in labels if "$" in s]
