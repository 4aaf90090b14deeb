"""The sensor-noise band of the validation figure: estimated from the error's own steps."""

import numpy as np
import pytest

from hystid.metrics import noise_level, plot_validation


def test_noise_level_sees_white_noise_not_a_slow_error_nor_outliers():
    rng = np.random.default_rng(0)
    t = np.arange(20_000) / 10_000.0
    white = 2.0 * rng.standard_normal(t.size)
    slow = 50.0 * np.sin(2 * np.pi * 0.5 * t)  # 25x the noise, far below the sampling rate
    e = white + slow
    e[::997] += 1e4  # outliers
    assert noise_level(e) == pytest.approx(2.0, rel=0.05)
    assert noise_level(np.ones(2)) == 0.0


def test_the_validation_figure_draws_the_band_and_a_loop_window(tmp_path):
    rng = np.random.default_rng(1)
    t = np.arange(5000) / 30_000.0
    u = np.sin(2 * np.pi * 50 * t)
    y = u + 1e-3 * rng.standard_normal(t.size)
    fig = plot_validation(t, y, u, tmp_path / "v.png", u=u)
    assert (tmp_path / "v.png").stat().st_size > 0
    err_ax = next(ax for ax in fig.axes if ax.get_ylabel().startswith("error"))
    assert any("sensor noise" in text.get_text() for text in err_ax.get_legend().get_texts())
    loop_ax = next(ax for ax in fig.axes if ax.get_xlabel().startswith("u ["))
    assert "around the largest error" in loop_ax.get_title()
