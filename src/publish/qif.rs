//! A scan's results as a QIF 3.0 Results document (ANSI/DMSC QIF 3.0, ISO 23952), valid
//! against the official schemas.
//!
//! Written by hand: no maintained Rust crate binds the QIF schemas, and the document is a
//! fixed shape. What goes where:
//!
//! - `MeasurementResources`: the instrument as a measurement device (maker, model, serial);
//! - `Product`: the part (`ModelNumber` the recipe's name, its description an attribute);
//! - `Characteristics`: one characteristic per specified parameter. QIF 3.0's
//!   `SurfaceTextureCharacteristic` carries only an ASME Y14.36 Ra value, with no side, rule
//!   or other parameter, so a callout such as `Rz max 6.3` has no place in it; each parameter
//!   is a `UserDefinedLinearCharacteristic` instead, whose `WhatToMeasure` names the surface
//!   texture parameter and its standard, and whose tolerance holds the limits (µm, as limits:
//!   `DefinedAsLimit`), or `NonTolerance` `MEASURED` for a scan without a specification;
//!   the callouts and the rule are attributes of the definition;
//! - `Results`: one measurement of each characteristic per line (`Value`, its status
//!   against the limits) and one for the surface (`Value` the mean over the lines with its
//!   expanded uncertainty as `combinedUncertainty`, `MinValue` and `MaxValue` over the
//!   lines, the characteristic's verdict as its status), the part's verdict as the
//!   inspection status, and the specimen as the actual component's serial number.
//!
//! Verdicts: *conforms* is `PASS`, *does not conform* `FAIL`, *not decidable*
//! `INDETERMINATE` for a characteristic and `UNKNOWN` for the part. The file's linear unit
//! is the micrometre.
//!
//! Layer 4 (the lab's systems): a pure formatter of [`Exported`]; the caller writes the bytes.

use super::exported::{decimal, Characteristic, Exported};
use crate::report::render::html::esc;
use crate::specification::Verdict;
use std::fmt::Write;

/// A UUID for the document, the same for the same scan (so a file exported again is the
/// same file): from the SHA-256 of the scan id, with the version 5 and variant bits.
pub fn document_uuid(scan_id: &str) -> String {
    let h = crate::scan::store::hex_sha256(format!("surfscan QIF results {scan_id}").as_bytes());
    let mut b: Vec<char> = h.chars().take(32).collect();
    b[12] = '5';
    b[16] = ['8', '9', 'a', 'b'][usize::from(b[16].to_digit(16).unwrap_or(0) as u8 & 3)];
    let s: String = b.into_iter().collect();
    format!(
        "{}-{}-{}-{}-{}",
        &s[0..8],
        &s[8..12],
        &s[12..16],
        &s[16..20],
        &s[20..32]
    )
}

fn characteristic_status(v: Option<Verdict>) -> &'static str {
    match v {
        Some(Verdict::Conforms) => "PASS",
        Some(Verdict::DoesNotConform) => "FAIL",
        Some(Verdict::NotDecidable) => "INDETERMINATE",
        None => "NOT_ANALYZED",
    }
}

fn inspection_status(v: Option<Verdict>) -> &'static str {
    match v {
        Some(Verdict::Conforms) => "PASS",
        Some(Verdict::DoesNotConform) => "FAIL",
        Some(Verdict::NotDecidable) | None => "UNKNOWN",
    }
}

/// The status of one line's value against the characteristic's limits, as the verdict's
/// lists of lines say it.
fn line_status(c: &Characteristic, number: u64) -> &'static str {
    if c.lower_um.is_none() && c.upper_um.is_none() {
        "NOT_ANALYZED"
    } else if c.lines_beyond.contains(&number) {
        "FAIL"
    } else if c.lines_undecided.contains(&number) {
        "INDETERMINATE"
    } else {
        "PASS"
    }
}

/// Writes `<tag>value</tag>` on a line of its own, `indent` spaces in; `value` as given (text
/// goes through [`esc`] first).
fn element(b: &mut String, indent: usize, tag: &str, value: impl std::fmt::Display) {
    let _ = writeln!(b, "{:indent$}<{tag}>{value}</{tag}>", "");
}

fn what_to_measure(c: &Characteristic, r: &Exported) -> String {
    let mut s = format!(
        "surface texture parameter {} (ISO 21920-2, ISO 4287) of each traced line over its evaluation length",
        c.parameter
    );
    if let (Some(lc), Some(n)) = (r.lambda_c_mm, r.sampling_lengths) {
        let _ = write!(s, ", λc {lc} mm, {n} sampling lengths");
    }
    s
}

struct Ids(u64);

impl Ids {
    fn next(&mut self) -> u64 {
        self.0 += 1;
        self.0
    }
}

/// The document's text (UTF-8).
pub fn qif(r: &Exported) -> String {
    let mut ids = Ids(0);
    let standard = ids.next();
    let device = ids.next();
    let part = ids.next();
    struct Ch {
        def: u64,
        nom: u64,
        item: u64,
    }
    let ch: Vec<Ch> = r
        .characteristics
        .iter()
        .map(|_| Ch {
            def: ids.next(),
            nom: ids.next(),
            item: ids.next(),
        })
        .collect();
    let mut body = String::new();
    let b = &mut body;

    // Results first (its ids are counted before the document's idMax is known).
    let results = ids.next();
    let component = ids.next();
    let mut measurements = String::new();
    let mut n_measurements = 0usize;
    let time = |t: Option<chrono::DateTime<chrono::Utc>>| {
        t.or(r.finished_at)
            .unwrap_or(r.started_at)
            .format("%Y-%m-%dT%H:%M:%SZ")
            .to_string()
    };
    // One measurement: its description, status, characteristic item, time and its value
    // elements.
    let mut measure = |description: String,
                       status: &str,
                       item: u64,
                       time: String,
                       value: String| {
        n_measurements += 1;
        let _ = write!(
            measurements,
            "          <UserDefinedLinearCharacteristicMeasurement id=\"{}\">\n            <Description>{description}</Description>\n            <Status><CharacteristicStatusEnum>{status}</CharacteristicStatusEnum></Status>\n            <CharacteristicItemId>{item}</CharacteristicItemId>\n            <TimeStamp>{time}</TimeStamp>\n            <MeasurementDeviceIds n=\"1\"><Id>{device}</Id></MeasurementDeviceIds>\n{value}          </UserDefinedLinearCharacteristicMeasurement>\n",
            ids.next()
        );
    };
    for (c, ids_c) in r.characteristics.iter().zip(&ch) {
        let finite: Vec<f64> = c.values_um.iter().flatten().copied().collect();
        if let Some(mean) = c.mean_um.filter(|m| m.is_finite()) {
            let u = c
                .expanded_u_um
                .filter(|u| u.is_finite())
                .map(|u| format!(" combinedUncertainty=\"{}\"", decimal(u)))
                .unwrap_or_default();
            let mut value = format!("            <Value{u}>{}</Value>\n", decimal(mean));
            if let (Some(hi), Some(lo)) = (
                finite.iter().copied().reduce(f64::max),
                finite.iter().copied().reduce(f64::min),
            ) {
                let _ = writeln!(value, "            <MaxValue>{}</MaxValue>", decimal(hi));
                let _ = writeln!(value, "            <MinValue>{}</MinValue>", decimal(lo));
            }
            measure(
                format!(
                    "{} of the surface: the mean of {} lines",
                    esc(&c.parameter),
                    c.n
                ),
                characteristic_status(c.verdict),
                ids_c.item,
                time(r.finished_at),
                value,
            );
        }
        for (k, line) in r.lines.iter().enumerate() {
            let Some(v) = c.values_um.get(k).copied().flatten() else {
                continue;
            };
            measure(
                format!(
                    "{} of line {} (y = {} mm)",
                    esc(&c.parameter),
                    line.number,
                    decimal(line.y_mm)
                ),
                line_status(c, line.number),
                ids_c.item,
                time(line.time),
                format!("            <Value>{}</Value>\n", decimal(v)),
            );
        }
    }

    let _ = writeln!(b, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>");
    let _ = writeln!(b, "<QIFDocument xmlns=\"http://qifstandards.org/xsd/qif3\" xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" xsi:schemaLocation=\"http://qifstandards.org/xsd/qif3 QIFApplications/QIFDocument.xsd\" versionQIF=\"3.0.0\" idMax=\"{}\">", ids.0);
    element(b, 2, "QPId", document_uuid(&r.scan_id));
    let _ = writeln!(b, "  <StandardsDefinitions n=\"1\">\n    <Standard id=\"{standard}\">\n      <Organization><StandardsOrganizationEnum>ISO</StandardsOrganizationEnum></Organization>\n      <Designator>21920-2</Designator>\n      <Year>2021</Year>\n      <Title>Geometrical product specifications (GPS) — Surface texture: Profile — Part 2: Terms, definitions and surface texture parameters</Title>\n    </Standard>\n  </StandardsDefinitions>");
    let _ = writeln!(b, "  <FileUnits>\n    <PrimaryUnits>\n      <LinearUnit>\n        <SIUnitName>meter</SIUnitName>\n        <UnitName>micrometre</UnitName>\n        <UnitConversion><Factor>0.000001</Factor></UnitConversion>\n      </LinearUnit>\n    </PrimaryUnits>\n  </FileUnits>");

    // The instrument.
    let _ = writeln!(
        b,
        "  <MeasurementResources>\n    <MeasurementDevices n=\"1\">"
    );
    let _ = writeln!(b, "      <MeasurementDevice id=\"{device}\">");
    let i = &r.instrument;
    element(
        b,
        8,
        "Name",
        esc(format!("{} {}", i.manufacturer, i.model).trim()),
    );
    let _ = writeln!(
        b,
        "        <Description>stylus profiler (firmware {})</Description>",
        esc(&i.firmware)
    );
    if !i.manufacturer.is_empty() {
        element(b, 8, "Manufacturer", esc(&i.manufacturer));
    }
    if !i.model.is_empty() {
        element(b, 8, "ModelNumber", esc(&i.model));
    }
    if let Some(s) = i.serial.as_deref().filter(|s| !s.is_empty()) {
        element(b, 8, "SerialNumber", esc(s));
    }
    let _ = writeln!(
        b,
        "      </MeasurementDevice>\n    </MeasurementDevices>\n  </MeasurementResources>"
    );

    // The part.
    let _ = writeln!(b, "  <Product>\n    <PartSet n=\"1\">");
    let _ = writeln!(b, "      <Part id=\"{part}\">");
    let _ = writeln!(b, "        <Attributes n=\"1\"><AttributeStr name=\"description\" value=\"{}\"/></Attributes>", esc(&r.part.description));
    element(b, 8, "ModelNumber", esc(&r.part.number));
    let _ = writeln!(b, "      </Part>\n    </PartSet>\n  </Product>");

    // The characteristics: definitions, nominals, items.
    let n = r.characteristics.len();
    let _ = writeln!(b, "  <Characteristics>");
    let _ = writeln!(b, "    <FormalStandardId>{standard}</FormalStandardId>");
    let _ = writeln!(b, "    <CharacteristicDefinitions n=\"{n}\">");
    for (c, id) in r.characteristics.iter().zip(&ch) {
        let _ = writeln!(
            b,
            "      <UserDefinedLinearCharacteristicDefinition id=\"{}\">",
            id.def
        );
        if !c.callouts.is_empty() {
            let _ = writeln!(
                b,
                "        <Attributes n=\"{}\">",
                c.callouts.len() + c.reasons.len()
            );
            // Each callout, then the verdict on each limit, numbered from 1.
            let callouts = c.callouts.iter().map(|t| ("callout", t)).zip(1..);
            let reasons = c.reasons.iter().map(|t| ("verdict", t)).zip(1..);
            for ((name, text), k) in callouts.chain(reasons) {
                let _ = writeln!(
                    b,
                    "          <AttributeStr name=\"{name} {k}\" value=\"{}\"/>",
                    esc(text)
                );
            }
            let _ = writeln!(b, "        </Attributes>");
        }
        element(b, 8, "Name", esc(&c.parameter));
        match (c.lower_um, c.upper_um) {
            (None, None) => {
                let _ = writeln!(b, "        <NonTolerance>MEASURED</NonTolerance>");
            }
            (lo, hi) => {
                let _ = writeln!(b, "        <Tolerance>");
                if let Some(hi) = hi {
                    element(b, 10, "MaxValue", decimal(hi));
                }
                if let Some(lo) = lo {
                    element(b, 10, "MinValue", decimal(lo));
                }
                let _ = writeln!(
                    b,
                    "          <DefinedAsLimit>true</DefinedAsLimit>\n        </Tolerance>"
                );
            }
        }
        element(b, 8, "WhatToMeasure", esc(&what_to_measure(c, r)));
        let _ = writeln!(b, "      </UserDefinedLinearCharacteristicDefinition>");
    }
    let _ = writeln!(b, "    </CharacteristicDefinitions>");
    let _ = writeln!(b, "    <CharacteristicNominals n=\"{n}\">");
    for (c, id) in r.characteristics.iter().zip(&ch) {
        let _ = writeln!(
            b,
            "      <UserDefinedLinearCharacteristicNominal id=\"{}\">",
            id.nom
        );
        element(b, 8, "CharacteristicDefinitionId", id.def);
        element(b, 8, "Name", esc(&c.parameter));
        let _ = writeln!(b, "      </UserDefinedLinearCharacteristicNominal>");
    }
    let _ = writeln!(b, "    </CharacteristicNominals>");
    let _ = writeln!(b, "    <CharacteristicItems n=\"{n}\">");
    for (c, id) in r.characteristics.iter().zip(&ch) {
        let _ = writeln!(
            b,
            "      <UserDefinedLinearCharacteristicItem id=\"{}\">",
            id.item
        );
        element(b, 8, "Name", esc(&c.parameter));
        let _ = writeln!(
            b,
            "        <MeasurementDeviceIds n=\"1\"><Id>{device}</Id></MeasurementDeviceIds>"
        );
        element(b, 8, "CharacteristicNominalId", id.nom);
        let _ = writeln!(b, "      </UserDefinedLinearCharacteristicItem>");
    }
    let _ = writeln!(b, "    </CharacteristicItems>");
    let _ = writeln!(b, "  </Characteristics>");

    // The results.
    let _ = writeln!(b, "  <Results>\n    <MeasurementResultsSet n=\"1\">");
    let _ = writeln!(b, "      <MeasurementResults id=\"{results}\">");
    if let Some(summary) = &r.verdict_summary {
        let _ = writeln!(b, "        <Attributes n=\"1\"><AttributeStr name=\"verdict\" value=\"{}\"/></Attributes>", esc(summary));
    }
    let _ = writeln!(b, "        <InspectionTraceability>");
    element(b, 10, "ReportNumber", esc(&r.scan_id));
    element(
        b,
        10,
        "InspectionStart",
        r.started_at.format("%Y-%m-%dT%H:%M:%SZ"),
    );
    if let Some(f) = r.finished_at {
        element(b, 10, "InspectionEnd", f.format("%Y-%m-%dT%H:%M:%SZ"));
    }
    if !r.operator.is_empty() {
        let _ = writeln!(
            b,
            "          <InspectionOperator><Name>{}</Name></InspectionOperator>",
            esc(&r.operator)
        );
    }
    let _ = writeln!(b, "        </InspectionTraceability>");
    if n_measurements > 0 {
        let _ = writeln!(b, "        <MeasuredCharacteristics>\n          <CharacteristicMeasurements n=\"{n_measurements}\">");
        b.push_str(&measurements.replace("\n          ", "\n            "));
        let _ = writeln!(
            b,
            "          </CharacteristicMeasurements>\n        </MeasuredCharacteristics>"
        );
    }
    let _ = writeln!(b, "        <InspectionStatus><InspectionStatusEnum>{}</InspectionStatusEnum></InspectionStatus>", inspection_status(r.verdict));
    let _ = writeln!(
        b,
        "        <ActualComponentIds n=\"1\"><Id>{component}</Id></ActualComponentIds>"
    );
    let _ = writeln!(
        b,
        "      </MeasurementResults>\n    </MeasurementResultsSet>"
    );
    let _ = writeln!(
        b,
        "    <ActualComponentSets n=\"1\">\n      <ActualComponentSet n=\"1\">"
    );
    let _ = writeln!(b, "        <ActualComponent id=\"{component}\">");
    if !r.specimen.is_empty() {
        element(b, 10, "SerialNumber", esc(&r.specimen));
    }
    let _ = writeln!(
        b,
        "          <Status><InspectionStatusEnum>{}</InspectionStatusEnum></Status>",
        inspection_status(r.verdict)
    );
    let _ = writeln!(
        b,
        "        </ActualComponent>\n      </ActualComponentSet>\n    </ActualComponentSets>"
    );
    let _ = writeln!(b, "  </Results>");
    let _ = writeln!(b, "</QIFDocument>");
    body
}
