//! The metrics file: [`super::metrics::ScanMetrics`] rendered and written atomically (temp
//! file, fsync, rename) for node_exporter's textfile collector, which so never reads a
//! half-written file.
//!
//! Layer 3 (session): depends on [`super::metrics`], [`super::faults`] for the durable
//! write and [`super::store_error`].

use std::path::Path;

use super::faults::{write_file_durably, StorageFaults, WriteStep};
use super::metrics::ScanMetrics;
use super::store_error::{io_err, StoreError};

/// Writes the metrics to `path` atomically (temp, fsync, rename, fsync of the directory).
pub fn write_metrics(
    path: &Path,
    metrics: &ScanMetrics,
    faults: &dyn StorageFaults,
) -> Result<(), StoreError> {
    write_file_durably(
        path,
        metrics.render().as_bytes(),
        WriteStep::Metrics,
        faults,
    )
    .map_err(io_err("write", path))
}
