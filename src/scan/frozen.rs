//! The settings that shape a scan's lines, frozen with the scan: a resumed scan runs its
//! remaining lines with the stage settings (backlash, steps, limits, settle, deadband, feed,
//! direction of approach) and the instrument's pitch, detector range and point-count check
//! its start record holds, not with a configuration edited since; the ports and the links'
//! serial settings are the configuration's (a device may have moved to another port). Every
//! difference is named, for the log and the journal; the configuration applies to the next
//! new scan.
//!
//! Layer 3 (session), pure: depends on the driver settings' types and `serde_json`.

use crate::sj210::settings::InstrumentSettings;
use crate::stage::StageSettings;

/// The instrument and stage settings a resumed scan runs with: `configured` (the current
/// configuration's) with what shapes the lines taken from `recorded` (the configuration as
/// the scan's start record holds it), and each difference for people. An error (the
/// configured settings then stand) when the record holds no readable `[stage]` or
/// `[instrument]`.
pub fn frozen(
    instrument: &InstrumentSettings,
    stage: &StageSettings,
    recorded: &serde_json::Value,
) -> Result<(InstrumentSettings, StageSettings, Vec<String>), String> {
    let mut rec_stage: StageSettings = serde_json::from_value(recorded["stage"].clone())
        .map_err(|e| format!("its recorded [stage] cannot be read ({e})"))?;
    let rec_instrument: InstrumentSettings = serde_json::from_value(recorded["instrument"].clone())
        .map_err(|e| format!("its recorded [instrument] cannot be read ({e})"))?;
    // How the devices are reached stays the configuration's.
    rec_stage.port = stage.port.clone();
    rec_stage.baud = stage.baud;
    rec_stage.parity = stage.parity;
    rec_stage.flow_control = stage.flow_control;
    rec_stage.device = stage.device;
    rec_stage.axis = stage.axis;
    rec_stage.poll_interval_ms = stage.poll_interval_ms;
    rec_stage.home_on_start = stage.home_on_start;
    let mut instr = instrument.clone();
    instr.pitch_x_um = rec_instrument.pitch_x_um;
    instr.detector_range_um = rec_instrument.detector_range_um;
    instr.check_point_count = rec_instrument.check_point_count;
    let mut named = differences("stage", stage, &rec_stage);
    named.extend(differences("instrument", instrument, &instr));
    Ok((instr, rec_stage, named))
}

/// `[table] key: the scan keeps A; the configuration now says B` for every key that differs.
fn differences<T: serde::Serialize>(table: &str, configured: &T, kept: &T) -> Vec<String> {
    let (Ok(serde_json::Value::Object(now)), Ok(serde_json::Value::Object(then))) =
        (serde_json::to_value(configured), serde_json::to_value(kept))
    else {
        return Vec::new();
    };
    let keys: std::collections::BTreeSet<&String> = now.keys().chain(then.keys()).collect();
    keys.into_iter()
        .filter_map(|k| {
            let (a, b) = (then.get(k), now.get(k));
            (a != b).then(|| {
                let show = |v: Option<&serde_json::Value>| {
                    v.map_or_else(|| "unset".to_owned(), |v| v.to_string())
                };
                format!(
                    "[{table}] {k}: the scan keeps {}; the configuration now says {} (applied to the next new scan)",
                    show(a),
                    show(b)
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings(text: &str) -> (InstrumentSettings, StageSettings, serde_json::Value) {
        let v: toml::Value = toml::from_str(text).unwrap();
        let json = serde_json::to_value(&v).unwrap();
        (
            serde_json::from_value(json["instrument"].clone()).unwrap(),
            serde_json::from_value(json["stage"].clone()).unwrap(),
            json,
        )
    }

    const RECORDED: &str = r#"
[instrument]
port = "/dev/sj210"
pitch-x-um = 1.5
[stage]
port = "/dev/ystage"
protocol = "grbl"
steps-per-mm = 400.0
soft-limit-min-mm = -100.0
soft-limit-max-mm = 0.0
backlash-mm = 0.05
"#;

    #[test]
    fn a_resumed_scan_keeps_its_backlash_and_pitch_and_takes_the_new_ports() {
        let (_, _, recorded) = settings(RECORDED);
        let edited = RECORDED
            .replace("backlash-mm = 0.05", "backlash-mm = 0.08")
            .replace("pitch-x-um = 1.5", "pitch-x-um = 0.5")
            .replace("/dev/ystage", "/dev/ttyUSB3");
        let (instrument, stage, _) = settings(&edited);
        let (i, s, diff) = frozen(&instrument, &stage, &recorded).unwrap();
        assert_eq!(s.backlash_mm, 0.05);
        assert_eq!(i.pitch_x_um, Some(1.5));
        assert_eq!(s.port, "/dev/ttyUSB3", "the port is the configuration's");
        assert_eq!(diff.len(), 2, "{diff:?}");
        assert!(
            diff.iter().any(|d| d.starts_with(
                "[stage] backlash-mm: the scan keeps 0.05; the configuration now says 0.08"
            )),
            "{diff:?}"
        );
        assert!(
            diff.iter()
                .any(|d| d.starts_with("[instrument] pitch-x-um: the scan keeps 1.5")),
            "{diff:?}"
        );
    }

    #[test]
    fn an_unchanged_configuration_gives_no_difference() {
        let (instrument, stage, recorded) = settings(RECORDED);
        let (i, s, diff) = frozen(&instrument, &stage, &recorded).unwrap();
        assert!(diff.is_empty(), "{diff:?}");
        assert_eq!((i, s), (instrument, stage));
    }

    #[test]
    fn a_record_without_stage_settings_is_named() {
        let (instrument, stage, _) = settings(RECORDED);
        let e = frozen(&instrument, &stage, &serde_json::json!({})).unwrap_err();
        assert!(e.contains("[stage]"), "{e}");
    }
}
