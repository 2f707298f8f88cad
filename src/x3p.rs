//! X3P (ISO 25178-72, the openGPS ISO 5436-2 XML format that Gwyddion and MountainsMap read
//! and write) of a regular height grid.
//!
//! The writer produces a zip archive (stored, uncompressed) holding `main.xml`,
//! `bindata/data.bin` (little-endian f64 heights in metres, x fastest) and `md5checksum.hex`,
//! a grid of one line as a profile (`PRF`, the (N, 1, 1) matrix ISO 5436-2 defines for it), any
//! other as a surface (`SUR`);
//! the MD5 it needs is RustCrypto's `md-5` and the CRC-32 is `crc32fast` (the tests check
//! them against the RFC 1321 vectors and the zip CRC's check value).
//!
//! The reader takes X3P files of other software too: stored or deflated zip entries (found
//! through the central directory, so data descriptors do not matter), surfaces (`SUR`) and
//! profiles (`PRF`) on incremental x/y axes, heights as int16/int32/float32/float64 (`I`, `L`,
//! `F`, `D`) in `bindata/*.bin` or as text in a `DataList`, scaled by the z axis's increment and
//! offset, invalid points from `ValidPointsLink` or non-finite values (returned as NaN), and
//! both MD5 sums checked when present. Deflate is miniz_oxide's, XML roxmltree's.
//!
//! Layer 1 (pure logic, a file format as [`crate::iges`] is): depends on
//! [`crate::metrology`]'s checks of heights and pitches and its height map only; takes and returns bytes (or
//! writes them to the caller's writer, [`X3p::write_to`]), the caller does the I/O.

use crate::metrology::areal::HeightMap;
use crate::metrology::{check_heights, check_pitch, MetrologyError};
use std::io::Write;

/// Traceability written into Record2 (free text; empty fields are written as "not available").
/// Record2 is written only when both `date` and `calibration_date` are stated (see [`to_x3p`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct X3pMeta {
    /// ISO 8601 date-time of the measurement.
    pub date: String,
    /// The instrument's calibration date (ISO 8601 date or date-time). Empty: no Record2 is
    /// written, since the schema requires a `CalibrationDate` in it and a made-up date could be
    /// read as a real one.
    pub calibration_date: String,
    /// The probing system's identification (stylus, tip radius); empty: the model.
    pub probe: String,
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

/// MD5 digest (RFC 1321), as the format's checksum files hold it (RustCrypto's `md-5`).
pub fn md5(data: &[u8]) -> [u8; 16] {
    use md5::Digest;
    md5::Md5::digest(data).into()
}

/// CRC-32 (IEEE 802.3, as zip uses), by `crc32fast`.
pub fn crc32(data: &[u8]) -> u32 {
    crc32fast::hash(data)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A Record2 field as read (the XML parser has unescaped it), "not available" as empty.
fn from_na(s: Option<&str>) -> String {
    match s {
        Some("not available") | None => String::new(),
        Some(v) => v.to_string(),
    }
}

fn or_na(s: &str) -> String {
    if s.trim().is_empty() {
        "not available".to_string()
    } else {
        xml_escape(s)
    }
}

/// One entry of a stored zip archive: its name, CRC-32 and size, and what writes its bytes.
struct ZipEntry<'a> {
    name: &'a str,
    crc: u32,
    size: u32,
    bytes: &'a dyn Fn(&mut dyn Write) -> std::io::Result<()>,
}

/// A zip archive of stored (uncompressed) entries, written to `w` entry by entry: no entry's
/// bytes need be held whole.
fn write_zip_stored(w: &mut dyn Write, entries: &[ZipEntry<'_>]) -> std::io::Result<()> {
    let mut offset = 0u32;
    let mut central = Vec::new();
    for e in entries {
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
            h.extend_from_slice(&e.crc.to_le_bytes());
            h.extend_from_slice(&e.size.to_le_bytes());
            h.extend_from_slice(&e.size.to_le_bytes());
            h.extend_from_slice(&(e.name.len() as u16).to_le_bytes());
            h.extend_from_slice(&0u16.to_le_bytes()); // extra
            if central {
                h.extend_from_slice(&0u16.to_le_bytes()); // comment
                h.extend_from_slice(&0u16.to_le_bytes()); // disk
                h.extend_from_slice(&0u16.to_le_bytes()); // internal attrs
                h.extend_from_slice(&0u32.to_le_bytes()); // external attrs
                h.extend_from_slice(&offset.to_le_bytes());
            }
            h.extend_from_slice(e.name.as_bytes());
            h
        };
        let local = header(0x0403_4b50, false);
        w.write_all(&local)?;
        (e.bytes)(w)?;
        central.extend(header(0x0201_4b50, true));
        offset += local.len() as u32 + e.size;
    }
    let mut end = Vec::new();
    end.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    end.extend_from_slice(&0u16.to_le_bytes());
    end.extend_from_slice(&0u16.to_le_bytes());
    end.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    end.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    end.extend_from_slice(&(central.len() as u32).to_le_bytes());
    end.extend_from_slice(&offset.to_le_bytes());
    end.extend_from_slice(&0u16.to_le_bytes());
    w.write_all(&central)?;
    w.write_all(&end)
}

/// `bindata/data.bin` of `heights_um` (little-endian f64 metres), passed to `f` a few
/// thousand heights at a time.
fn data_bin(
    heights_um: &[f64],
    mut f: impl FnMut(&[u8]) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(8 * 4096);
    for chunk in heights_um.chunks(4096) {
        buf.clear();
        buf.extend(chunk.iter().flat_map(|z| (z * 1e-6).to_le_bytes()));
        f(&buf)?;
    }
    Ok(())
}

/// A length in mm as metres rounded to the picometre, so that a pitch of 0.01 mm is written
/// `1e-5` and not with the float noise of the mean it came from (`1.0000000000000009e-5`).
/// Integer picometres divided by 10¹² give the double nearest the decimal value.
fn metres(mm: f64) -> f64 {
    (mm * 1e9).round() / 1e12
}

/// An ISO 8601 date (`2025-03-14`) as the xsd:dateTime the format wants; a date-time as it is.
fn as_datetime(d: &str) -> String {
    let d = d.trim();
    if d.len() == 10 && d.as_bytes().get(4) == Some(&b'-') && d.as_bytes().get(7) == Some(&b'-') {
        format!("{d}T00:00:00")
    } else {
        d.to_string()
    }
}

/// Record2, the metadata, with its line end; empty when `meta` states no calibration date or no
/// date. ISO 5436-2's schema makes `Date` and `CalibrationDate` mandatory in Record2 and
/// Record2 itself optional: without a stated calibration date the file carries no Record2
/// rather than a made-up date that could be read as a real calibration (report.json keeps the
/// instrument, operator and conditions of a scan either way).
fn record2(meta: &X3pMeta) -> String {
    if meta.calibration_date.trim().is_empty() || meta.date.trim().is_empty() {
        return String::new();
    }
    format!(
        "<Record2><Date>{date}</Date><Creator>{creator}</Creator><Instrument><Manufacturer>{man}</Manufacturer><Model>{model}</Model><Serial>{serial}</Serial><Version>{version}</Version></Instrument><CalibrationDate>{calibration}</CalibrationDate><ProbingSystem><Type>Contacting</Type><Identification>{probe}</Identification></ProbingSystem><Comment>{comment}</Comment></Record2>\n",
        date = xml_escape(&meta.date),
        creator = or_na(&meta.creator),
        man = or_na(&meta.manufacturer),
        model = or_na(&meta.model),
        serial = or_na(&meta.serial),
        version = or_na(&meta.version),
        calibration = xml_escape(&as_datetime(&meta.calibration_date)),
        probe = if meta.probe.trim().is_empty() {
            or_na(&meta.model)
        } else {
            xml_escape(&meta.probe)
        },
        comment = or_na(&meta.comment),
    )
}

/// The X3P archive of a height map (heights µm, `rows` lines along y, `cols` points along x,
/// row-major): a profile (`PRF`) when it is one line, else a surface (`SUR`). `origin_mm` is
/// the x of each line's first point and the machine y of the first line, written as the CX and
/// CY axis offsets so that the file places the grid where it was measured. `main.xml` is valid against
/// the ISO 5436-2 schema (`tests/data/x3p/iso5436_2.xsd`); Record2 is left out when `meta`
/// states no calibration date.
pub fn x3p<'a>(
    map: &HeightMap<'a>,
    origin_mm: (f64, f64),
    meta: &X3pMeta,
) -> Result<X3p<'a>, MetrologyError> {
    let &HeightMap {
        heights_um,
        rows,
        cols,
        pitch_x_mm,
        pitch_y_mm,
    } = map;
    if !(origin_mm.0.is_finite() && origin_mm.1.is_finite()) {
        return Err(bad(format!(
            "the x, y of the first point ({origin_mm:?} mm) are not finite numbers"
        )));
    }
    map.check_size(1)?;
    check_heights(heights_um)?;
    let (mut data_md5, mut crc) = (<md5::Md5 as md5::Digest>::new(), crc32fast::Hasher::new());
    data_bin(heights_um, |b| {
        md5::Digest::update(&mut data_md5, b);
        crc.update(b);
        Ok(())
    })
    .expect("hashing cannot fail");
    let data_md5 = hex(&md5::Digest::finalize(data_md5));
    let xml = format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:schemaLocation="http://www.opengps.eu/2008/ISO5436_2 http://www.opengps.eu/2008/ISO5436_2/ISO5436_2.xsd">
<Record1><Revision>ISO5436 - 2000</Revision><FeatureType>{feature}</FeatureType><Axes>
<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>{ix:e}</Increment><Offset>{ox:e}</Offset></CX>
<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>{iy:e}</Increment><Offset>{oy:e}</Offset></CY>
<CZ><AxisType>A</AxisType><DataType>D</DataType><Increment>1</Increment><Offset>0</Offset></CZ>
</Axes></Record1>
{record2}<Record3><MatrixDimension><SizeX>{cols}</SizeX><SizeY>{rows}</SizeY><SizeZ>1</SizeZ></MatrixDimension><DataLink><PointDataLink>bindata/data.bin</PointDataLink><MD5ChecksumPointData>{data_md5}</MD5ChecksumPointData></DataLink></Record3>
<Record4><ChecksumFile>md5checksum.hex</ChecksumFile></Record4>
</p:ISO5436_2>
"#,
        feature = if rows == 1 { "PRF" } else { "SUR" },
        ix = metres(pitch_x_mm),
        iy = metres(pitch_y_mm),
        ox = metres(origin_mm.0),
        oy = metres(origin_mm.1),
        record2 = record2(meta),
    );
    let checksum = format!("{} *main.xml\n", hex(&md5(xml.as_bytes())));
    Ok(X3p {
        heights_um,
        data_crc: crc.finalize(),
        xml,
        checksum,
    })
}

/// An X3P archive ready to be written ([`x3p`]): the checked grid, its `main.xml` and the
/// checksums.
#[derive(Debug, Clone)]
pub struct X3p<'a> {
    heights_um: &'a [f64],
    data_crc: u32,
    xml: String,
    checksum: String,
}

impl X3p<'_> {
    /// Writes the archive to `w`, the heights converted a few thousand at a time: a grid of
    /// 10⁷ heights needs no 80 MB copy of its bytes.
    pub fn write_to(&self, w: &mut dyn Write) -> std::io::Result<()> {
        let size = |b: &[u8]| b.len() as u32;
        let xml = |w: &mut dyn Write| w.write_all(self.xml.as_bytes());
        let checksum = |w: &mut dyn Write| w.write_all(self.checksum.as_bytes());
        let data = |w: &mut dyn Write| data_bin(self.heights_um, |b| w.write_all(b));
        write_zip_stored(
            w,
            &[
                ZipEntry {
                    name: "main.xml",
                    crc: crc32(self.xml.as_bytes()),
                    size: size(self.xml.as_bytes()),
                    bytes: &xml,
                },
                ZipEntry {
                    name: "bindata/data.bin",
                    crc: self.data_crc,
                    size: (self.heights_um.len() * 8) as u32,
                    bytes: &data,
                },
                ZipEntry {
                    name: "md5checksum.hex",
                    crc: crc32(self.checksum.as_bytes()),
                    size: size(self.checksum.as_bytes()),
                    bytes: &checksum,
                },
            ],
        )
    }
}

/// [`x3p`]'s archive as bytes.
pub fn to_x3p(
    map: &HeightMap<'_>,
    origin_mm: (f64, f64),
    meta: &X3pMeta,
) -> Result<Vec<u8>, MetrologyError> {
    let file = x3p(map, origin_mm, meta)?;
    let mut bytes = Vec::new();
    file.write_to(&mut bytes)
        .expect("writing to memory cannot fail");
    Ok(bytes)
}

/// A grid read from an X3P file.
#[derive(Debug, Clone, PartialEq)]
pub struct X3pGrid {
    /// Heights in µm, row-major (x fastest); invalid points are NaN.
    pub heights_um: Vec<f64>,
    /// Rows (SizeY): lines along y.
    pub rows: usize,
    /// Columns (SizeX): points along x.
    pub cols: usize,
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// y pitch, mm (1 for a profile without a y axis).
    pub pitch_y_mm: f64,
    /// x of each line's first point, mm: the CX axis offset (0 when the file gives none).
    pub offset_x_mm: f64,
    /// y of the first line, mm: the CY axis offset (0 when the file gives none).
    pub offset_y_mm: f64,
    /// `SUR` (a surface) or `PRF` (a profile).
    pub feature_type: String,
    /// Points the file marks invalid (not measured), NaN in `heights_um`.
    pub invalid_points: usize,
    /// Record2 as written ("not available" read back as an empty field).
    pub meta: X3pMeta,
}

/// Why an X3P file cannot be read: what is wrong, with the value found.
fn bad(what: impl Into<String>) -> MetrologyError {
    MetrologyError::X3p {
        reason: what.into(),
    }
}

/// One zip entry: its name and its (decompressed) bytes.
struct Entry {
    name: String,
    data: Vec<u8>,
}

fn u16_at(b: &[u8], i: usize) -> Option<usize> {
    b.get(i..i + 2)
        .map(|v| u16::from_le_bytes([v[0], v[1]]) as usize)
}

fn u32_at(b: &[u8], i: usize) -> Option<u32> {
    b.get(i..i + 4)
        .map(|v| u32::from_le_bytes([v[0], v[1], v[2], v[3]]))
}

/// Largest entry the reader inflates (a 31 × 100 000 f64 grid is 25 MB).
const MAX_ENTRY_BYTES: usize = 1 << 30;

/// The entries of a zip archive, from its central directory.
fn entries(zip: &[u8]) -> Result<Vec<Entry>, MetrologyError> {
    if !zip.starts_with(b"PK") {
        return Err(bad(
            "not a zip archive (an X3P file is a zip of main.xml and the data)",
        ));
    }
    // The end-of-central-directory record: the last "PK\x05\x06" (a comment may follow it).
    let Some(eocd) = (0..zip.len().saturating_sub(21))
        .rev()
        .take(65_557)
        .find(|&i| u32_at(zip, i) == Some(0x0605_4b50))
    else {
        return local_entries(zip);
    };
    let count = u16_at(zip, eocd + 10).ok_or_else(|| bad("zip directory"))?;
    let mut p = u32_at(zip, eocd + 16).ok_or_else(|| bad("zip directory"))? as usize;
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        if u32_at(zip, p) != Some(0x0201_4b50) {
            return Err(bad(format!(
                "zip central directory entry at byte {p} is damaged"
            )));
        }
        let field = |off: usize| u16_at(zip, p + off).ok_or_else(|| bad("zip directory"));
        let method = field(10)?;
        let crc = u32_at(zip, p + 16).ok_or_else(|| bad("zip directory"))?;
        let csize = u32_at(zip, p + 20).ok_or_else(|| bad("zip directory"))? as usize;
        let usize_ = u32_at(zip, p + 24).ok_or_else(|| bad("zip directory"))? as usize;
        let (name_len, extra_len, comment_len) = (field(28)?, field(30)?, field(32)?);
        let local = u32_at(zip, p + 42).ok_or_else(|| bad("zip directory"))? as usize;
        let name = zip
            .get(p + 46..p + 46 + name_len)
            .ok_or_else(|| bad("zip entry name"))?;
        let name = String::from_utf8_lossy(name).into_owned();
        p += 46 + name_len + extra_len + comment_len;
        if u32_at(zip, local) != Some(0x0403_4b50) {
            return Err(bad(format!("{name}: its zip header is damaged")));
        }
        let l_name = u16_at(zip, local + 26).ok_or_else(|| bad("zip header"))?;
        let l_extra = u16_at(zip, local + 28).ok_or_else(|| bad("zip header"))?;
        let start = local + 30 + l_name + l_extra;
        let raw = zip.get(start..start + csize).ok_or_else(|| {
            bad(format!(
                "{name}: the archive ends inside it (truncated file?)"
            ))
        })?;
        let data = inflate(&name, method, raw, usize_, crc)?;
        out.push(Entry { name, data });
    }
    Ok(out)
}

/// The entries of an archive without a central directory (cut short, or written by a
/// streaming tool), from its local headers in order; an entry whose sizes are deferred to a
/// data descriptor cannot be found this way.
fn local_entries(zip: &[u8]) -> Result<Vec<Entry>, MetrologyError> {
    let mut out = Vec::new();
    let mut p = 0usize;
    while u32_at(zip, p) == Some(0x0403_4b50) {
        let field = |off: usize| u16_at(zip, p + off).ok_or_else(|| bad("zip header"));
        let (flags, method) = (field(6)?, field(8)?);
        let crc = u32_at(zip, p + 14).ok_or_else(|| bad("zip header"))?;
        let csize = u32_at(zip, p + 18).ok_or_else(|| bad("zip header"))? as usize;
        let usize_ = u32_at(zip, p + 22).ok_or_else(|| bad("zip header"))? as usize;
        let (name_len, extra_len) = (field(26)?, field(28)?);
        let name = zip
            .get(p + 30..p + 30 + name_len)
            .ok_or_else(|| bad("zip entry name"))?;
        let name = String::from_utf8_lossy(name).into_owned();
        if flags & 0x08 != 0 {
            return Err(bad(format!(
                "{name}: its sizes follow its data and the archive has no central directory (truncated file?)"
            )));
        }
        let start = p + 30 + name_len + extra_len;
        let raw = zip.get(start..start + csize).ok_or_else(|| {
            bad(format!(
                "{name}: the archive ends inside it (truncated file?)"
            ))
        })?;
        out.push(Entry {
            data: inflate(&name, method, raw, usize_, crc)?,
            name,
        });
        p = start + csize;
    }
    if out.is_empty() {
        return Err(bad(
            "the zip archive has no readable entry (truncated file?)",
        ));
    }
    Ok(out)
}

/// The bytes of an entry stored (method 0) or deflated (8), checked against its size and
/// CRC-32.
fn inflate(
    name: &str,
    method: usize,
    raw: &[u8],
    size: usize,
    crc: u32,
) -> Result<Vec<u8>, MetrologyError> {
    let data = match method {
        0 => raw.to_vec(),
        8 => {
            miniz_oxide::inflate::decompress_to_vec_with_limit(raw, size.clamp(1, MAX_ENTRY_BYTES))
                .map_err(|e| bad(format!("{name}: cannot inflate ({e:?})")))?
        }
        m => {
            return Err(bad(format!(
                "{name}: zip compression method {m} (only stored and deflate are read)"
            )))
        }
    };
    if data.len() != size || crc32(&data) != crc {
        return Err(bad(format!(
            "{name}: CRC-32 or size does not match (damaged file)"
        )));
    }
    Ok(data)
}

/// The first descendant of `node` whose local name (without namespace) is `name`.
fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, name: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children()
        .find(|n| n.is_element() && n.tag_name().name() == name)
}

/// The trimmed text of the element at `path` (local names) below `node`.
fn text_at<'a>(node: roxmltree::Node<'a, '_>, path: &[&str]) -> Option<&'a str> {
    let mut n = node;
    for p in path {
        n = child(n, p)?;
    }
    n.text().map(str::trim)
}

fn number(node: roxmltree::Node<'_, '_>, path: &[&str]) -> Result<Option<f64>, MetrologyError> {
    match text_at(node, path) {
        None | Some("") => Ok(None),
        Some(t) => t.parse::<f64>().map(Some).map_err(|_| {
            bad(format!(
                "main.xml: {} is {t:?}, not a number",
                path.join("/")
            ))
        }),
    }
}

/// Reads an X3P archive (ours or another program's, see the module docs), checking its
/// checksums.
pub fn read_x3p(zip: &[u8]) -> Result<X3pGrid, MetrologyError> {
    let entries = entries(zip)?;
    let get = |n: &str| {
        let n = n.trim().trim_start_matches("./");
        entries.iter().find(|e| e.name == n).map(|e| &e.data[..])
    };
    let xml_bytes = get("main.xml").ok_or_else(|| bad("the archive holds no main.xml"))?;
    if let Some(sums) = get("md5checksum.hex") {
        let want = String::from_utf8_lossy(sums);
        let want = want.split_whitespace().next().unwrap_or("");
        if !want.eq_ignore_ascii_case(&hex(&md5(xml_bytes))) {
            return Err(bad(
                "main.xml does not match its MD5 in md5checksum.hex (damaged file)",
            ));
        }
    }
    let xml =
        std::str::from_utf8(xml_bytes).map_err(|e| bad(format!("main.xml is not UTF-8 ({e})")))?;
    let doc = roxmltree::Document::parse(xml).map_err(|e| bad(format!("main.xml: {e}")))?;
    let root = doc.root_element();
    let r1 = child(root, "Record1").ok_or_else(|| bad("main.xml has no Record1"))?;
    let r3 = child(root, "Record3").ok_or_else(|| bad("main.xml has no Record3"))?;
    let feature = text_at(r1, &["FeatureType"]).unwrap_or("").to_string();
    if feature != "SUR" && feature != "PRF" {
        return Err(bad(format!(
            "FeatureType {feature:?}: only surfaces (SUR) and profiles (PRF) are read, not point clouds"
        )));
    }
    let axes = child(r1, "Axes").ok_or_else(|| bad("main.xml has no Record1/Axes"))?;
    for a in ["CX", "CY"] {
        if let Some(t) = child(axes, a).and_then(|n| text_at(n, &["AxisType"])) {
            if t != "I" {
                return Err(bad(format!(
                    "axis {a} is of type {t:?}: only incremental (I) x and y axes form a grid"
                )));
            }
        }
    }
    let cx = child(axes, "CX").ok_or_else(|| bad("main.xml has no CX axis"))?;
    let pitch_x_m = number(cx, &["Increment"])?.ok_or_else(|| bad("CX has no Increment"))?;
    let offset_x_m = number(cx, &["Offset"])?;
    let (pitch_y_m, offset_y_m) = match child(axes, "CY") {
        Some(cy) => (number(cy, &["Increment"])?, number(cy, &["Offset"])?),
        None => (None, None),
    };
    let cz = child(axes, "CZ").ok_or_else(|| bad("main.xml has no CZ axis"))?;
    let z_type = text_at(cz, &["DataType"]).unwrap_or("D").to_string();
    let z_inc = number(cz, &["Increment"])?.unwrap_or(1.0);
    let z_off = number(cz, &["Offset"])?.unwrap_or(0.0);
    // xsd:unsignedInt in ISO 5436-2; a size read as a real (1e300) would overflow rows × cols.
    let size = |n: &str| -> Result<usize, MetrologyError> {
        let t = text_at(r3, &["MatrixDimension", n])
            .ok_or_else(|| bad(format!("Record3/MatrixDimension has no {n}")))?;
        t.parse::<usize>()
            .map_err(|_| bad(format!("MatrixDimension/{n} is {t:?}, not a whole number")))
    };
    let (cols, rows) = (size("SizeX")?, size("SizeY")?);
    if size("SizeZ")? != 1 {
        return Err(bad("several layers (SizeZ > 1) are not read"));
    }
    let n = rows
        .checked_mul(cols)
        .filter(|&n| n > 0)
        .ok_or_else(|| bad(format!("grid of {rows} × {cols} points")))?;
    // Nothing is allocated from the sizes main.xml claims before the data confirm them.
    let mut raw: Vec<f64> = Vec::new();
    let mut valid: Option<Vec<bool>> = None;
    if let Some(link) = child(r3, "DataLink") {
        let name = text_at(link, &["PointDataLink"])
            .ok_or_else(|| bad("DataLink has no PointDataLink"))?;
        let data = get(name).ok_or_else(|| bad(format!("the archive holds no {name}")))?;
        if let Some(want) = text_at(link, &["MD5ChecksumPointData"]) {
            if !want.eq_ignore_ascii_case(&hex(&md5(data))) {
                return Err(bad(format!(
                    "{name} does not match its MD5 in main.xml (damaged file)"
                )));
            }
        }
        let width = match z_type.as_str() {
            "I" => 2,
            "L" | "F" => 4,
            "D" => 8,
            t => return Err(bad(format!("CZ DataType {t:?} (expected I, L, F or D)"))),
        };
        if n.checked_mul(width) != Some(data.len()) {
            return Err(bad(format!(
                "{name} holds {} bytes, but {rows} × {cols} points of type {z_type} need {}",
                data.len(),
                n.saturating_mul(width)
            )));
        }
        raw.extend(data.chunks_exact(width).map(|b| match b {
            [a, b] => f64::from(i16::from_le_bytes([*a, *b])),
            [a, b, c, d] if z_type == "L" => f64::from(i32::from_le_bytes([*a, *b, *c, *d])),
            [a, b, c, d] => f64::from(f32::from_le_bytes([*a, *b, *c, *d])),
            [a, b, c, d, e, f, g, h] => f64::from_le_bytes([*a, *b, *c, *d, *e, *f, *g, *h]),
            _ => f64::NAN,
        }));
        if let Some(vname) = text_at(link, &["ValidPointsLink"]) {
            let bits = get(vname).ok_or_else(|| bad(format!("the archive holds no {vname}")))?;
            if bits.len() * 8 < n {
                return Err(bad(format!(
                    "{vname} has {} bits for {n} points",
                    bits.len() * 8
                )));
            }
            // One bit per point, least significant bit first; a set bit is a valid point.
            valid = Some((0..n).map(|k| bits[k / 8] >> (k % 8) & 1 == 1).collect());
        }
    } else if let Some(list) = child(r3, "DataList") {
        for d in list.children().filter(|c| c.is_element()) {
            let t = d.text().map(str::trim).unwrap_or("");
            raw.push(if t.is_empty() {
                f64::NAN
            } else {
                t.parse()
                    .map_err(|_| bad(format!("DataList Datum {:?} is not a number", t)))?
            });
        }
        if raw.len() != n {
            return Err(bad(format!(
                "DataList holds {} values for {rows} × {cols} points",
                raw.len()
            )));
        }
    } else {
        return Err(bad("Record3 has neither a DataLink nor a DataList"));
    }
    let mut invalid_points = 0;
    let heights_um: Vec<f64> = raw
        .iter()
        .enumerate()
        .map(|(k, v)| {
            let ok = valid.as_ref().is_none_or(|m| m[k]);
            let z = (v * z_inc + z_off) * 1e6;
            if ok && z.is_finite() {
                z
            } else {
                invalid_points += 1;
                f64::NAN
            }
        })
        .collect();
    let pitch_x_mm = pitch_x_m * 1e3;
    let pitch_y_mm = match pitch_y_m {
        Some(p) => p * 1e3,
        None if rows == 1 => 1.0,
        None => return Err(bad("CY has no Increment")),
    };
    check_pitch(pitch_x_mm)?;
    check_pitch(pitch_y_mm)?;
    let offset_mm = |axis: &str, m: Option<f64>| {
        let mm = m.unwrap_or(0.0) * 1e3;
        match mm.is_finite() {
            true => Ok(mm),
            false => Err(bad(format!("{axis} Offset {mm} mm is not a finite number"))),
        }
    };
    let (offset_x_mm, offset_y_mm) = (offset_mm("CX", offset_x_m)?, offset_mm("CY", offset_y_m)?);
    let meta = match child(root, "Record2") {
        Some(r2) => {
            let f = |path: &[&str]| from_na(text_at(r2, path));
            X3pMeta {
                date: f(&["Date"]),
                calibration_date: f(&["CalibrationDate"]),
                probe: f(&["ProbingSystem", "Identification"]),
                creator: f(&["Creator"]),
                manufacturer: f(&["Instrument", "Manufacturer"]),
                model: f(&["Instrument", "Model"]),
                serial: f(&["Instrument", "Serial"]),
                version: f(&["Instrument", "Version"]),
                comment: f(&["Comment"]),
            }
        }
        None => X3pMeta::default(),
    };
    Ok(X3pGrid {
        heights_um,
        rows,
        cols,
        pitch_x_mm,
        pitch_y_mm,
        offset_x_mm,
        offset_y_mm,
        feature_type: feature,
        invalid_points,
        meta,
    })
}
