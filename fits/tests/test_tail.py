"""The unresolved-tail cut (data_formats/objective.md, "The tail the scan cannot resolve") and the CSV's
``unresolved`` column."""

import numpy as np
import pytest

from ndfitpy.bins import Bins, read_ndf_csv
from ndfitpy.tail import cut_core, cut_rim, cut_unresolved, whitened_lambert_radius


def _bins(count, unresolved):
    k = len(count)
    m = np.tile([0.0, 0.0, 1.0], (k, 1))
    b = Bins(m=m, count=np.asarray(count, float), proj_solid_angle=np.full(k, 0.1))
    b.extra["unresolved"] = None if unresolved is None else np.asarray(unresolved, float)
    return b


def test_majority_unresolved_bins_leave_and_n_total_keeps_every_normal():
    """Bins with 2 u > c leave (u = c/2 exactly stays); the whole NDF's count stays N."""
    b = _bins([100, 40, 10, 7, 0], [0, 20, 6, 7, 0])
    cut, info = cut_unresolved(b)
    assert list(cut.count) == [100, 40, 0]
    assert info.rule == "unresolved" and info.bins_excluded == 2 and info.n_excluded == 17
    assert info.unresolved_fraction == pytest.approx(33 / 157)
    assert cut.n_samples == 157


def test_rough_at_the_sampling_step_cuts_nothing():
    """Over a quarter of all normals unresolved: the guard keeps every bin."""
    b = _bins([100, 40, 10], [30, 20, 6])
    cut, info = cut_unresolved(b)
    assert len(cut) == 3 and info.rule.startswith("none (rough")


def test_without_the_column_nothing_is_cut():
    cut, info = cut_unresolved(_bins([5, 6], None))
    assert len(cut) == 2 and info.rule == "none"


def test_csv_column_is_read_and_checked(tmp_path):
    head = "mx,my,mz,d,stderr,count,solid_angle,proj_solid_angle,slope_x,slope_y,unresolved\n"
    row = "0,0,1,1,0.1,{c},0.1,0.1,0,0,{u}\n"
    p = tmp_path / "a.csv"
    p.write_text(head + row.format(c=3, u=2) + row.format(c=4, u=0))
    assert list(read_ndf_csv(str(p)).extra["unresolved"]) == [2, 0]
    p.write_text(head + row.format(c=3, u="") + row.format(c=4, u=""))
    assert read_ndf_csv(str(p)).extra["unresolved"] is None
    p.write_text(head + row.format(c=3, u=5))
    with pytest.raises(ValueError, match="line 2: unresolved"):
        read_ndf_csv(str(p))


def test_whitened_lambert_radius_closed_form():
    """|p| = 2 sin(theta'/2) of the whitened normal: a slope at the frame's centre is 0; whitened slope
    radius sqrt 3 (theta' = 60 degrees) is exactly 1, the core's edge."""
    frame = {"center": [0.1, -0.2], "whiten": [[2.0, 0.0], [0.0, 4.0]]}
    s = np.array([[0.1, -0.2], [0.1 + np.sqrt(3.0) / 2.0, -0.2], [0.1, -0.2 + np.sqrt(3.0) / 4.0]])
    m = np.column_stack([-s, np.ones(3)])
    assert whitened_lambert_radius(m, frame) == pytest.approx([0.0, 1.0, 1.0], abs=1e-12)


def test_core_rule_keeps_the_core_when_the_tail_is_unresolved():
    """With 5% of the region's normals in a majority-unresolved bin the bins beyond |p| = 1 leave (N stays
    the whole NDF's count); with the same bin only 20% unresolved (no unresolved bin) nothing does; rough at
    the sampling step (29% unresolved), nothing does."""
    frame = {"center": [0.0, 0.0], "whiten": [[1.0, 0.0], [0.0, 1.0]]}
    r = np.array([0.0, 1.0, 1.5, 2.0])  # whitened slope radius: |p| = 0, 0.765, 0.944, 1.051 (63 deg)
    m = np.column_stack([-r, np.zeros(4), np.ones(4)])
    p = whitened_lambert_radius(m, frame)
    assert list(p <= 1.0) == [True, True, True, False]
    b = Bins(m=m, count=np.array([500.0, 300.0, 150.0, 50.0]), proj_solid_angle=np.full(4, 0.1))
    b.extra["unresolved"] = np.array([0.0, 0.0, 0.0, 10.0])
    cut, info = cut_core(b, frame)
    assert info.rule == "none (tail resolved)" and len(cut) == 4
    b.extra["unresolved"] = np.array([0.0, 0.0, 0.0, 30.0])
    cut, info = cut_core(b, frame)
    assert info.rule == "core" and list(cut.count) == [500, 300, 150] and cut.n_samples == 1000
    b.extra["unresolved"] = np.array([200.0, 60.0, 0.0, 30.0])
    cut, info = cut_core(b, frame)
    assert info.rule.startswith("none (rough") and len(cut) == 4


def test_rim_rule_cuts_the_core_of_a_lone_rim_and_only_unresolved_bins_under_another_lobe():
    """The default rule on the bins above: all 30 unresolved normals in the one bin they dominate (a lone
    lobe's rim): the core cut, as cut_core. The same bin, plus 40 unresolved normals spread over bins of
    resolved ones (another lobe covering the rim: 30 of 70 alone, under half): only that bin leaves, the
    resolved bin beyond |p| = 1 stays."""
    frame = {"center": [0.0, 0.0], "whiten": [[1.0, 0.0], [0.0, 1.0]]}
    r = np.array([0.0, 1.0, 1.5, 2.0, 2.5])  # |p| = 0, 0.765, 0.944, 1.051, 1.15
    m = np.column_stack([-r, np.zeros(5), np.ones(5)])
    b = Bins(m=m, count=np.array([500.0, 300.0, 150.0, 200.0, 50.0]), proj_solid_angle=np.full(5, 0.1))
    b.extra["unresolved"] = np.array([0.0, 0.0, 0.0, 0.0, 30.0])
    cut, info = cut_rim(b, frame)
    core, core_info = cut_core(b, frame)
    assert info == core_info and info.rule == "core" and list(cut.count) == list(core.count) == [500, 300, 150]
    b.extra["unresolved"] = np.array([0.0, 0.0, 20.0, 20.0, 30.0])
    cut, info = cut_rim(b, frame)
    assert info.rule == "unresolved" and list(cut.count) == [500, 300, 150, 200] and cut.n_samples == 1200
    assert info.bins_excluded == 1 and info.n_excluded == 50
    b.extra["unresolved"] = np.array([0.0, 0.0, 0.0, 0.0, 5.0])
    cut, info = cut_rim(b, frame)
    assert info.rule == "none (tail resolved)" and len(cut) == 5
