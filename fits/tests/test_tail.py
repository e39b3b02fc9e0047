"""The unresolved-tail cut (data_formats/objective.md, "The tail the scan cannot resolve") and the CSV's
``unresolved`` column."""

import numpy as np
import pytest

from ndfitpy.bins import Bins, read_ndf_csv
from ndfitpy.tail import cut_unresolved


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
