//! The scan: plan, durable line storage and journal, resume, and the runner that drives instrument, stage and fitter.
//!
//! Layer 3: depends on the device contracts ([`crate::devices`]), the fitter and the IGES writer.
