"""Writes X3P files the way other software does, for surfscan's X3P reader to read.

Usage: python3 x3p_write.py DIR

Writes into DIR, and prints as JSON what each file holds (heights in µm, row-major, null for an
invalid point; pitches in mm), from the values put in, not from reading the files back:

- surfalize-d.x3p: surfalize's own writer (deflated zip entries, float64 heights).
- surfalize-f-nan.x3p: surfalize's writer with float32 heights and two non-measured points (NaN).
- int16-valid.x3p: written here with zipfile and ElementTree as ISO 25178-72 describes it: int16
  heights scaled by the z axis's increment and offset, a validity bit mask (bindata/valid.bin,
  least significant bit first) marking one point invalid, deflated entries, a prefixed root
  namespace, Record2 with a calibration date.
- profile-datalist.x3p: a profile (FeatureType PRF, one line) whose heights are text in a
  DataList, stored (not deflated), no CY increment.
"""

import hashlib
import json
import sys
import zipfile
from pathlib import Path
import xml.etree.ElementTree as ET

import numpy as np
from surfalize import Surface

NS = "http://www.opengps.eu/2008/ISO5436_2"


def grid(rows, cols):
    y, x = np.mgrid[0:rows, 0:cols]
    return 0.8 * np.sin(x * 0.21 + y * 0.5) + 0.05 * y - 0.3


def as_json(z, step_x_um, step_y_um):
    return {
        "rows": int(z.shape[0]),
        "cols": int(z.shape[1]),
        "pitch_x_mm": step_x_um / 1000.0,
        "pitch_y_mm": step_y_um / 1000.0,
        "heights_um": [None if np.isnan(v) else float(v) for v in z.ravel()],
    }


def main_xml(feature, cols, rows, cx_inc_m, cy_inc_m, z_type, z_inc, z_off, data_link, record2):
    root = ET.Element("p:ISO5436_2", {"xmlns:p": NS})
    r1 = ET.SubElement(root, "Record1")
    ET.SubElement(r1, "Revision").text = "ISO5436 - 2000"
    ET.SubElement(r1, "FeatureType").text = feature
    axes = ET.SubElement(r1, "Axes")
    for name, inc in (("CX", cx_inc_m), ("CY", cy_inc_m)):
        a = ET.SubElement(axes, name)
        ET.SubElement(a, "AxisType").text = "I"
        ET.SubElement(a, "DataType").text = "D"
        if inc is not None:
            ET.SubElement(a, "Increment").text = repr(inc)
        ET.SubElement(a, "Offset").text = "0"
    cz = ET.SubElement(axes, "CZ")
    ET.SubElement(cz, "AxisType").text = "A"
    ET.SubElement(cz, "DataType").text = z_type
    ET.SubElement(cz, "Increment").text = repr(z_inc)
    ET.SubElement(cz, "Offset").text = repr(z_off)
    root.append(record2)
    r3 = ET.SubElement(root, "Record3")
    md = ET.SubElement(r3, "MatrixDimension")
    ET.SubElement(md, "SizeX").text = str(cols)
    ET.SubElement(md, "SizeY").text = str(rows)
    ET.SubElement(md, "SizeZ").text = "1"
    r3.append(data_link)
    r4 = ET.SubElement(root, "Record4")
    ET.SubElement(r4, "ChecksumFile").text = "md5checksum.hex"
    ET.indent(root)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode")).encode()


def record2(calibration):
    r2 = ET.Element("Record2")
    ET.SubElement(r2, "Date").text = "2024-05-06T07:08:09+02:00"
    ET.SubElement(r2, "Creator").text = "A. Person & Co"
    inst = ET.SubElement(r2, "Instrument")
    ET.SubElement(inst, "Manufacturer").text = "Example Optics"
    ET.SubElement(inst, "Model").text = "Profiler 9"
    ET.SubElement(inst, "Serial").text = "SN 42"
    ET.SubElement(inst, "Version").text = "3.1"
    ET.SubElement(r2, "CalibrationDate").text = calibration
    ps = ET.SubElement(r2, "ProbingSystem")
    ET.SubElement(ps, "Type").text = "NonContacting"
    ET.SubElement(ps, "Identification").text = "50x objective"
    ET.SubElement(r2, "Comment").text = "written by x3p_write.py"
    return r2


def write_zip(path, members, compression):
    xml = members[0][1]
    with zipfile.ZipFile(path, "w", compression=compression) as z:
        for name, data in members:
            z.writestr(name, data)
        z.writestr("md5checksum.hex", f"{hashlib.md5(xml).hexdigest()} *main.xml\n")


def main():
    out = Path(sys.argv[1])
    files = {}

    z = grid(6, 40)
    Surface(z, 1.5, 1.5).save(out / "surfalize-d.x3p")
    files["surfalize-d.x3p"] = as_json(z, 1.5, 1.5)

    z = grid(5, 200)
    z[1, 3] = np.nan
    z[4, 199] = np.nan
    Surface(z, 2.0, 10.0).save(out / "surfalize-f-nan.x3p", dtype="F")
    # float32 metres in the file.
    files["surfalize-f-nan.x3p"] = as_json((z / 1e6).astype(np.float32).astype(np.float64) * 1e6, 2.0, 10.0)

    rows, cols = 4, 25
    raw = np.round(grid(rows, cols) * 1000).astype("<i2")  # nm
    z_inc, z_off = 1e-9, 2e-6  # m per count, m
    valid = np.ones(rows * cols, dtype=bool)
    valid[7] = False
    link = ET.Element("DataLink")
    ET.SubElement(link, "PointDataLink").text = "bindata/data.bin"
    ET.SubElement(link, "MD5ChecksumPointData").text = hashlib.md5(raw.tobytes()).hexdigest().upper()
    ET.SubElement(link, "ValidPointsLink").text = "bindata/valid.bin"
    xml = main_xml("SUR", cols, rows, 1.0e-6, 5.0e-6, "I", z_inc, z_off, link, record2("2024-01-31T00:00:00"))
    write_zip(
        out / "int16-valid.x3p",
        [("main.xml", xml), ("bindata/data.bin", raw.tobytes()),
         ("bindata/valid.bin", np.packbits(valid, bitorder="little").tobytes())],
        zipfile.ZIP_DEFLATED,
    )
    heights = (raw.astype(np.float64) * z_inc + z_off) * 1e6
    heights.ravel()[~valid] = np.nan
    files["int16-valid.x3p"] = as_json(heights.reshape(rows, cols), 1.0, 5.0)

    cols = 30
    prof = grid(1, cols)[0] * 1e-6  # m
    link = ET.Element("DataList")
    for v in prof:
        ET.SubElement(link, "Datum").text = repr(float(v))
    xml = main_xml("PRF", cols, 1, 0.5e-6, None, "D", 1.0, 0.0, link, record2("2023-12-01T00:00:00"))
    write_zip(out / "profile-datalist.x3p", [("main.xml", xml)], zipfile.ZIP_STORED)
    files["profile-datalist.x3p"] = as_json((prof * 1e6)[None, :], 0.5, 1000.0)

    json.dump(files, sys.stdout)


if __name__ == "__main__":
    main()
