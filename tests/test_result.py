"""IdentificationResult.plot: a matplotlib Figure of the parameter history, without pyplot."""

import io

import numpy as np
import pytest

from hystid.identify import identify
from hystid.reference import PAPER_PARAMS


@pytest.fixture(scope="module")
def results():
    """On-line results keeping a decimated history and none, on a record of the independent
    simulator with a sensor offset."""
    from hystid.testing import paper_excitation, paper_stage, record_from, with_noise, with_offset

    simulator = paper_stage()
    u = paper_excitation(0.05, simulator.fs, seed=7)
    rec = with_offset(with_noise(record_from(simulator.simulate(u, u_rest=0.0), simulator.fs,
                                             "offset stage"), 1e-3, seed=7), 0.3)
    online = identify(rec, method="online", history="decimated", history_rows=100)
    without = identify(rec, method="online", history="none")
    return online, without


def test_plot_returns_a_figure_without_touching_pyplot(results):
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    online, _ = results
    before = plt.get_fignums()
    fig = online.plot(truth=PAPER_PARAMS)
    assert plt.get_fignums() == before
    assert isinstance(fig, Figure)
    names = online.names
    assert [ax.get_ylabel() for ax in fig.axes] == list(names)
    assert fig.axes[-1].get_xlabel() == "sample k"
    for ax, column in zip(fig.axes, online.history.T, strict=True):
        trace, *truth_lines = ax.get_lines()
        assert np.array_equal(trace.get_xdata(), online.history_index)  # decimated rows
        assert np.array_equal(trace.get_ydata(), column)
        assert [line.get_linestyle() for line in truth_lines] == ["--"]
        assert truth_lines[0].get_ydata()[0] == PAPER_PARAMS[ax.get_ylabel()]
    png = io.BytesIO()
    fig.savefig(png, format="png")
    assert png.getvalue()[:8] == b"\x89PNG\r\n\x1a\n"
    assert plt.get_fignums() == before


def test_plot_draws_into_given_axes_and_returns_their_figure(results):
    from matplotlib.figure import Figure

    online, _ = results
    mine = Figure()
    grid = mine.subplots(3, 2)
    assert online.plot(axes=grid) is mine
    assert [ax.get_ylabel() for ax in grid.ravel()] == list(online.names)
    with pytest.raises(ValueError, match="axes: expected 6 axes"):
        online.plot(axes=Figure().subplots(2, 1))


def test_plot_without_a_history_says_so(results):
    _, without = results
    assert without.history is None
    with pytest.raises(ValueError, match="'online' keeps no parameter history"):
        without.plot()
