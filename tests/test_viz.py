"""ogm_ppl.viz: the reliability diagram draws what it is given."""

import numpy as np

from ogm_ppl.metrics import reliability
from ogm_ppl.viz import _plt, plot_reliability


def test_plot_reliability_draws_each_diagram_and_the_diagonal():
    plt = _plt()
    q = np.array([0.05, 0.15, 0.12, 0.55, 0.95, 1.0])
    m = np.array([False, True, False, True, True, False])
    r = reliability(q, m)
    ax = plot_reliability({"a": r, "b": reliability(q, ~m)}, min_count=2)
    lines = ax.get_lines()
    assert len(lines) == 3  # the diagonal and two diagrams
    np.testing.assert_allclose(lines[1].get_xdata(), [0.135, 0.975])  # bins holding >= 2 cells
    np.testing.assert_allclose(lines[1].get_ydata(), [0.5, 0.5])
    assert "ECE 0.363" in ax.get_legend().get_texts()[0].get_text()
    plt.close(ax.figure)
    ax = plot_reliability({"one": r})  # one diagram: the share of cells per bin as bars
    bars = [p.get_height() for p in ax.figure.axes[1].patches]
    np.testing.assert_allclose(bars, r.count / 6)
    plt.close(ax.figure)
