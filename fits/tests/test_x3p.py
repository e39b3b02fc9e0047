"""The notebooks' minimal X3P reader on files written here by hand (ISO 25178-72 layout)."""

import zipfile

import numpy as np
import pytest

from ndfitpy.x3p import read_x3p

MAIN = """<?xml version="1.0" encoding="UTF-8"?>
<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2">
<Record1><Revision>ISO5436 - 2000</Revision><FeatureType>SUR</FeatureType><Axes>
<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>2.5e-06</Increment><Offset>0</Offset></CX>
<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>5e-06</Increment><Offset>0</Offset></CY>
<CZ><AxisType>A</AxisType><DataType>{dt}</DataType><Increment>{inc}</Increment><Offset>{off}</Offset></CZ>
</Axes></Record1>
<Record3><MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>
<DataLink><PointDataLink>bindata/data.bin</PointDataLink></DataLink></Record3>
</p:ISO5436_2>"""


def _write(path, z_raw, dt, inc=1.0, off=0.0, folder=""):
    ny, nx = z_raw.shape
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(folder + "main.xml", MAIN.format(dt=dt, inc=inc, off=off, nx=nx, ny=ny))
        zf.writestr(folder + "bindata/data.bin", z_raw.astype({"D": "<f8", "F": "<f4", "L": "<i4", "I": "<i2"}[dt]).tobytes())


def test_float64_with_nan_and_rows_along_y(tmp_path):
    z = np.arange(12, dtype=float).reshape(3, 4) * 1e-6
    z[1, 2] = np.nan
    p = tmp_path / "a.x3p"
    _write(p, z, "D")
    h = read_x3p(p)
    np.testing.assert_array_equal(h.z, z)  # x fastest: row i is y, column j is x
    assert (h.dx, h.dy) == (2.5e-06, 5e-06)


def test_integer_heights_use_increment_and_offset_in_a_subfolder(tmp_path):
    raw = np.array([[0, 1, -2], [300, 4, 5]])
    p = tmp_path / "b.x3p"
    _write(p, raw, "L", inc=1e-9, off=2e-6, folder="scan/")
    np.testing.assert_allclose(read_x3p(p).z, raw * 1e-9 + 2e-6, rtol=1e-15)


def test_bad_files(tmp_path):
    p = tmp_path / "c.x3p"
    p.write_text("not a zip")
    with pytest.raises(ValueError, match="not an X3P"):
        read_x3p(p)
    q = tmp_path / "d.x3p"
    with zipfile.ZipFile(q, "w") as zf:
        zf.writestr("main.xml", MAIN.format(dt="D", inc=1, off=0, nx=4, ny=4))
        zf.writestr("bindata/data.bin", b"\0" * 8)
    with pytest.raises(ValueError, match="bytes"):
        read_x3p(q)
