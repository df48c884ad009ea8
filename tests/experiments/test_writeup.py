"""The public summary helpers of :mod:`mrfpe.experiments.writeup`."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mrfpe.experiments.writeup import fmt, markdown_table, mean_sd, new_figure, save_figure


@pytest.mark.parametrize(("mean", "sd", "text"), [
    (0.609612, 0.0123, "0.610 ± 0.012"),
    (0.6096123, 3.2e-6, "0.6096123 ± 0.0000032"),
    (1234.5, 56.0, "1234 ± 56"),
    (12345.0, 678.0, "12340 ± 680"),
    (0.5, 0.0, "0.5 ± 0 (no spread)"),
])
def test_mean_sd_shows_the_digits_the_sd_supports(mean, sd, text):
    assert mean_sd(mean, sd) == text


@given(st.floats(-1e6, 1e6), st.floats(1e-9, 1e5))
def test_mean_sd_sd_has_two_significant_digits(mean, sd):
    shown = mean_sd(mean, sd).split(" ± ")[1]
    value = float(shown)
    assert math.isclose(value, sd, rel_tol=0.06, abs_tol=0)  # rounded to 2 digits


def test_tables_format_numbers_and_missing_values():
    assert fmt(None) == "–" and fmt(float("nan")) == "–" and fmt(3) == "3"
    assert markdown_table(["a", "b"], [[1, 0.123456]]).splitlines()[-1] == "| 1 | 0.1235 |"


def test_save_figure_hides_empty_panels(tmp_path):
    fig, axes = new_figure(2, 2)
    for ax in axes.ravel()[:3]:
        ax.plot([0, 1], [1, 0])
    assert save_figure(fig, tmp_path / "f.png") == "f.png" and (tmp_path / "f.png").is_file()
    assert [ax.get_visible() for ax in axes.ravel()] == [True, True, True, False]
