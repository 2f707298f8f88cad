//! The traceability a scan's outputs carry: the IGES Start-section lines and the
//! `traceability` block of the fallback `report.json`.
//!
//! Layer 3 (session): depends on the journal's start record and the plan.

use super::journal::StartRecord;
use super::plan::Plan;

/// The Start-section lines that make an IGES file of a scan traceable.
pub fn traceability_lines(start: &StartRecord, plan: &Plan) -> Vec<String> {
    let c = &start.conditions;
    vec![
        format!(
            "Surface fitted by {} ({}, p={}, q={}); units mm.",
            start.software_version,
            plan.v_method.in_brief(),
            plan.degree_u,
            plan.degree_v
        ),
        format!(
            "Scan {}: specimen {:?}, operator {:?}, notes {:?}.",
            start.scan_id, start.specimen, start.operator, start.notes
        ),
        format!(
            "Instrument Mitutoyo {} firmware {:?}, drive unit {:?}; conditions: standard {}, profile {}, lambda-c {} mm, lambda-s {} um, evaluation length {} mm.",
            start.instrument_model,
            start.firmware,
            start.drive_unit,
            c.standard.as_deref().unwrap_or("unknown"),
            c.profile_kind.map_or("unknown".to_owned(), |k| format!("{k:?}")),
            c.lambda_c_mm.map_or("unknown".to_owned(), |v| v.to_string()),
            c.lambda_s_um.map_or("unknown".to_owned(), |v| v.to_string()),
            c.evaluation_length_mm.map_or("unknown".to_owned(), |v| v.to_string()),
        ),
        format!(
            "Grid: {} lines from y = {} mm by {} mm; config sha256 {}; started {}.",
            plan.lines,
            plan.y_start_nm.to_mm(),
            plan.y_step_nm.to_mm(),
            start.config_hash,
            start.time.to_rfc3339()
        ),
    ]
}

/// The traceability block of `report.json`.
pub fn traceability_json(start: &StartRecord) -> serde_json::Value {
    serde_json::json!({
        "scan_id": start.scan_id,
        "specimen": start.specimen,
        "operator": start.operator,
        "notes": start.notes,
        "software_version": start.software_version,
        "config_hash": start.config_hash,
        "instrument_model": start.instrument_model,
        "firmware": start.firmware,
        "drive_unit": start.drive_unit,
        "conditions": start.conditions,
        "started": start.time,
    })
}
