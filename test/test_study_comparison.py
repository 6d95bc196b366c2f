"""Tests of rotation_dev.study.comparison: accuracy and cost of the two-stream estimates."""
import pytest
from rotation_dev.study import comparison as study


@pytest.mark.slow
def test_quick_rows_meet_the_targets_and_render():
    rows = study.measure(quick=True)
    assert [(r.noise_deg, r.duration_s) for r in rows] == [
        (noise, duration) for duration in study.QUICK_DURATIONS_S
        for noise in study.QUICK_NOISE_DEG]
    for r in rows:
        assert r.time_offset_error_s < 1e-3 and 0.0 < r.time_offset_std_s < 1e-3
        assert r.world_error_deg < 0.1 and r.mounting_error_deg < 0.1
        assert abs(r.rmse_ratio - 1.0) < 0.05
        assert r.offset_seconds > 0.0 and r.alignment_seconds > 0.0
    text = study.comparison_markdown(rows, heading='## 8.')
    assert text.startswith('## 8. Two streams') and text.count('\n| 0.3 | 10 |') == 1
    assert study.comparison_png(rows).startswith(b'\x89PNG')
