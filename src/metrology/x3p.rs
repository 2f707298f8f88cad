//! X3P (ISO 25178-72, the openGPS ISO 5436-2 XML format that Gwyddion and MountainsMap read) of a
//! regular height grid: a zip archive (stored, uncompressed) holding `main.xml`,
//! `bindata/data.bin` (little-endian f64 heights in metres, x fastest) and `md5checksum.hex`.
//! The MD5 and CRC-32 the format needs are implemented here (small, tested against the RFC
//! vectors) so no archive or digest dependency is needed. A reader for the files this writer
//! produces is included for round trips.
//!
//! Depends on [`super::MetrologyError`] only; returns bytes, the caller writes the file.

use super::{check_finite, check_pitch, MetrologyError};

/// Traceability written into Record2 (free text; empty fields are written as "not available").
#[derive(Debug, Clone, Default, PartialEq)]
pub struct X3pMeta {
    /// ISO 8601 date-time of the measurement.
    pub date: String,
    /// Operator or creator.
    pub creator: String,
    /// Instrument manufacturer.
    pub manufacturer: String,
    /// Instrument model.
    pub model: String,
    /// Instrument serial number.
    pub serial: String,
    /// Software / firmware version.
    pub version: String,
    /// Free comment: specimen, conditions, what the grid is (measured or model).
    pub comment: String,
}

/// MD5 digest (RFC 1321).
pub fn md5(data: &[u8]) -> [u8; 16] {
    const S: [u32; 64] = [
        7, 12, 17, 22, 7, 12, 17, 22, 7, 12, 17, 22, 7, 12, 17, 22, 5, 9, 14, 20, 5, 9, 14, 20, 5,
        9, 14, 20, 5, 9, 14, 20, 4, 11, 16, 23, 4, 11, 16, 23, 4, 11, 16, 23, 4, 11, 16, 23, 6, 10,
        15, 21, 6, 10, 15, 21, 6, 10, 15, 21, 6, 10, 15, 21,
    ];
    let k: Vec<u32> = (0..64)
        .map(|i| ((i as f64 + 1.0).sin().abs() * 4_294_967_296.0) as u32)
        .collect();
    let mut msg = data.to_vec();
    let bit_len = (data.len() as u64).wrapping_mul(8);
    msg.push(0x80);
    while msg.len() % 64 != 56 {
        msg.push(0);
    }
    msg.extend_from_slice(&bit_len.to_le_bytes());
    let (mut a0, mut b0, mut c0, mut d0) = (
        0x6745_2301u32,
        0xefcd_ab89u32,
        0x98ba_dcfeu32,
        0x1032_5476u32,
    );
    for chunk in msg.chunks_exact(64) {
        let m: Vec<u32> = chunk
            .chunks_exact(4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        let (mut a, mut b, mut c, mut d) = (a0, b0, c0, d0);
        for i in 0..64 {
            let (f, g) = match i / 16 {
                0 => ((b & c) | (!b & d), i),
                1 => ((d & b) | (!d & c), (5 * i + 1) % 16),
                2 => (b ^ c ^ d, (3 * i + 5) % 16),
                _ => (c ^ (b | !d), (7 * i) % 16),
            };
            let f = f.wrapping_add(a).wrapping_add(k[i]).wrapping_add(m[g]);
            a = d;
            d = c;
            c = b;
            b = b.wrapping_add(f.rotate_left(S[i]));
        }
        a0 = a0.wrapping_add(a);
        b0 = b0.wrapping_add(b);
        c0 = c0.wrapping_add(c);
        d0 = d0.wrapping_add(d);
    }
    let mut out = [0u8; 16];
    for (o, w) in out.chunks_exact_mut(4).zip([a0, b0, c0, d0]) {
        o.copy_from_slice(&w.to_le_bytes());
    }
    out
}

/// CRC-32 (IEEE 802.3, as zip uses).
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &byte in data {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn xml_unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&")
}

fn from_na(s: Option<&str>) -> String {
    match s {
        Some("not available") | None => String::new(),
        Some(v) => xml_unescape(v),
    }
}

fn or_na(s: &str) -> String {
    if s.trim().is_empty() {
        "not available".to_string()
    } else {
        xml_escape(s)
    }
}

/// A zip archive of stored (uncompressed) entries.
fn zip_stored(entries: &[(&str, &[u8])]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in entries {
        let offset = out.len() as u32;
        let crc = crc32(data);
        let size = data.len() as u32;
        let header = |sig: u32, central: bool| {
            let mut h = Vec::new();
            h.extend_from_slice(&sig.to_le_bytes());
            if central {
                h.extend_from_slice(&20u16.to_le_bytes()); // version made by
            }
            h.extend_from_slice(&20u16.to_le_bytes()); // version needed
            h.extend_from_slice(&0u16.to_le_bytes()); // flags
            h.extend_from_slice(&0u16.to_le_bytes()); // method: stored
            h.extend_from_slice(&0u16.to_le_bytes()); // time
            h.extend_from_slice(&0x21u16.to_le_bytes()); // date 1980-01-01
            h.extend_from_slice(&crc.to_le_bytes());
            h.extend_from_slice(&size.to_le_bytes());
            h.extend_from_slice(&size.to_le_bytes());
            h.extend_from_slice(&(name.len() as u16).to_le_bytes());
            h.extend_from_slice(&0u16.to_le_bytes()); // extra
            if central {
                h.extend_from_slice(&0u16.to_le_bytes()); // comment
                h.extend_from_slice(&0u16.to_le_bytes()); // disk
                h.extend_from_slice(&0u16.to_le_bytes()); // internal attrs
                h.extend_from_slice(&0u32.to_le_bytes()); // external attrs
                h.extend_from_slice(&offset.to_le_bytes());
            }
            h.extend_from_slice(name.as_bytes());
            h
        };
        out.extend(header(0x0403_4b50, false));
        out.extend_from_slice(data);
        central.extend(header(0x0201_4b50, true));
    }
    let cd_offset = out.len() as u32;
    let cd_size = central.len() as u32;
    out.extend(central);
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&cd_size.to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out
}

/// The X3P archive of a row-major grid (heights µm, `rows` lines along y, `cols` points along x).
pub fn to_x3p(
    heights_um: &[f64],
    rows: usize,
    cols: usize,
    pitch_x_mm: f64,
    pitch_y_mm: f64,
    meta: &X3pMeta,
) -> Result<Vec<u8>, MetrologyError> {
    check_pitch(pitch_x_mm)?;
    check_pitch(pitch_y_mm)?;
    if rows.checked_mul(cols) != Some(heights_um.len()) || rows == 0 || cols == 0 {
        return Err(MetrologyError::GridSize {
            rows,
            cols,
            expected: rows.saturating_mul(cols),
            got: heights_um.len(),
        });
    }
    check_finite(heights_um)?;
    let data: Vec<u8> = heights_um
        .iter()
        .flat_map(|z| (z * 1e-6).to_le_bytes())
        .collect();
    let data_md5 = hex(&md5(&data));
    let xml = format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:schemaLocation="http://www.opengps.eu/2008/ISO5436_2 http://www.opengps.eu/2008/ISO5436_2/ISO5436_2.xsd">
<Record1><Revision>ISO5436 - 2000</Revision><FeatureType>SUR</FeatureType><Axes>
<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>{ix:e}</Increment><Offset>0</Offset></CX>
<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>{iy:e}</Increment><Offset>0</Offset></CY>
<CZ><AxisType>A</AxisType><DataType>D</DataType><Increment>1</Increment><Offset>0</Offset></CZ>
</Axes></Record1>
<Record2><Date>{date}</Date><Creator>{creator}</Creator><Instrument><Manufacturer>{man}</Manufacturer><Model>{model}</Model><Serial>{serial}</Serial><Version>{version}</Version></Instrument><CalibrationDate>{date}</CalibrationDate><ProbingSystem><Type>Contacting</Type><Identification>{model}</Identification></ProbingSystem><Comment>{comment}</Comment></Record2>
<Record3><MatrixDimension><SizeX>{cols}</SizeX><SizeY>{rows}</SizeY><SizeZ>1</SizeZ></MatrixDimension><DataLink><PointDataLink>bindata/data.bin</PointDataLink><MD5ChecksumPointData>{data_md5}</MD5ChecksumPointData></DataLink></Record3>
<Record4><ChecksumFile>md5checksum.hex</ChecksumFile></Record4>
</p:ISO5436_2>
"#,
        ix = pitch_x_mm * 1e-3,
        iy = pitch_y_mm * 1e-3,
        date = if meta.date.trim().is_empty() {
            "1970-01-01T00:00:00Z".to_string()
        } else {
            xml_escape(&meta.date)
        },
        creator = or_na(&meta.creator),
        man = or_na(&meta.manufacturer),
        model = or_na(&meta.model),
        serial = or_na(&meta.serial),
        version = or_na(&meta.version),
        comment = or_na(&meta.comment),
    );
    let checksum = format!("{} *main.xml\n", hex(&md5(xml.as_bytes())));
    Ok(zip_stored(&[
        ("main.xml", xml.as_bytes()),
        ("bindata/data.bin", &data),
        ("md5checksum.hex", checksum.as_bytes()),
    ]))
}

/// A grid read back from an X3P written by [`to_x3p`].
#[derive(Debug, Clone, PartialEq)]
pub struct X3pGrid {
    /// Heights in µm, row-major.
    pub heights_um: Vec<f64>,
    /// Rows (SizeY).
    pub rows: usize,
    /// Columns (SizeX).
    pub cols: usize,
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// y pitch, mm.
    pub pitch_y_mm: f64,
    /// Record2 as written ("not available" read back as an empty field).
    pub meta: X3pMeta,
}

fn bad(what: &'static str) -> MetrologyError {
    MetrologyError::BadParameter {
        what,
        value: 0.0,
        hint: "not an X3P archive of stored entries as this software writes",
    }
}

fn entries(zip: &[u8]) -> Result<Vec<(String, &[u8])>, MetrologyError> {
    let mut out = Vec::new();
    let mut p = 0usize;
    let u16_at = |i: usize| {
        zip.get(i..i + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]) as usize)
    };
    let u32_at = |i: usize| {
        zip.get(i..i + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    while u32_at(p) == Some(0x0403_4b50) {
        if u16_at(p + 8) != Some(0) {
            return Err(bad("compressed zip entry"));
        }
        let size = u32_at(p + 18).ok_or(bad("zip header"))? as usize;
        let name_len = u16_at(p + 26).ok_or(bad("zip header"))?;
        let extra = u16_at(p + 28).ok_or(bad("zip header"))?;
        let name = zip.get(p + 30..p + 30 + name_len).ok_or(bad("zip name"))?;
        let start = p + 30 + name_len + extra;
        let data = zip.get(start..start + size).ok_or(bad("zip data"))?;
        out.push((String::from_utf8_lossy(name).into_owned(), data));
        p = start + size;
    }
    Ok(out)
}

fn tag<'a>(xml: &'a str, outer: &str, name: &str) -> Option<&'a str> {
    let o = xml.find(&format!("<{outer}>"))?;
    let rest = xml.get(o..)?;
    let s = rest.find(&format!("<{name}>"))? + name.len() + 2;
    let e = rest.get(s..)?.find(&format!("</{name}>"))? + s;
    rest.get(s..e).map(str::trim)
}

/// Reads back an archive written by [`to_x3p`], checking both MD5 sums.
pub fn read_x3p(zip: &[u8]) -> Result<X3pGrid, MetrologyError> {
    let entries = entries(zip)?;
    let get = |n: &str| entries.iter().find(|(k, _)| k == n).map(|(_, d)| *d);
    let xml_bytes = get("main.xml").ok_or(bad("main.xml missing"))?;
    let data = get("bindata/data.bin").ok_or(bad("bindata/data.bin missing"))?;
    let sums = get("md5checksum.hex").ok_or(bad("md5checksum.hex missing"))?;
    if !String::from_utf8_lossy(sums).starts_with(&hex(&md5(xml_bytes))) {
        return Err(bad("main.xml MD5 mismatch"));
    }
    let xml = String::from_utf8_lossy(xml_bytes);
    if tag(&xml, "DataLink", "MD5ChecksumPointData") != Some(hex(&md5(data)).as_str()) {
        return Err(bad("data.bin MD5 mismatch"));
    }
    let num = |outer: &str, name: &str| -> Result<f64, MetrologyError> {
        tag(&xml, outer, name)
            .and_then(|v| v.parse::<f64>().ok())
            .ok_or(bad("numeric field missing"))
    };
    // xsd:unsignedInt in ISO 5436-2; a size read as a real (1e300) would overflow rows × cols.
    let size = |name: &str| -> Result<usize, MetrologyError> {
        tag(&xml, "MatrixDimension", name)
            .and_then(|v| v.parse::<usize>().ok())
            .ok_or(bad("matrix size missing or not a whole number"))
    };
    let cols = size("SizeX")?;
    let rows = size("SizeY")?;
    let heights_um: Vec<f64> = data
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) * 1e6)
        .collect();
    if rows.checked_mul(cols) != Some(heights_um.len()) {
        return Err(MetrologyError::GridSize {
            rows,
            cols,
            expected: rows.saturating_mul(cols),
            got: heights_um.len(),
        });
    }
    Ok(X3pGrid {
        heights_um,
        rows,
        cols,
        pitch_x_mm: num("CX", "Increment")? * 1e3,
        pitch_y_mm: num("CY", "Increment")? * 1e3,
        meta: X3pMeta {
            date: from_na(tag(&xml, "Record2", "Date")),
            creator: from_na(tag(&xml, "Record2", "Creator")),
            manufacturer: from_na(tag(&xml, "Instrument", "Manufacturer")),
            model: from_na(tag(&xml, "Instrument", "Model")),
            serial: from_na(tag(&xml, "Instrument", "Serial")),
            version: from_na(tag(&xml, "Instrument", "Version")),
            comment: from_na(tag(&xml, "Record2", "Comment")),
        },
    })
}
