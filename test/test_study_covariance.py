"""Tests of rotation_dev.study.covariance: first-order Euler covariance against Monte Carlo."""
import pytest
from rotation_dev.study import covariance as study


@pytest.mark.slow
def test_study_finds_where_linearisation_holds_and_where_it_breaks():
    rows = study.measure(quick=True)
    assert {r.sweep for r in rows} == {'sigma', 'margin'}
    for r in rows:
        if r.ratio <= 0.03:   # first order exact to the sampling error
            assert r.worst_error < 2 * r.statistical_error, r
        if r.ratio >= 1.0:    # and far off once sigma reaches the distance to gimbal lock
            assert r.worst_error > 0.2, r
    assert 0.05 <= study.trusted_ratio(rows, 0.1) <= 1.0
    assert study.trusted_ratio(rows, 0.01) <= study.trusted_ratio(rows, 0.1)


@pytest.mark.slow
def test_section_and_plot():
    rows = study.measure(quick=True)
    text = study.covariance_markdown(rows, heading='##')
    assert text.startswith('## Euler-angle covariance')
    assert text.count('| sigma (deg) |') == 2 and '**Verdict:**' in text
    assert study.covariance_png(rows).startswith(b'\x89PNG')
