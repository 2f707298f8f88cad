//! Writing a fitted surface as IGES: `surface.igs`, or several complete files
//! `surface.part<i>-of-<n>.igs` of whole exact patches when one file cannot hold it (the P
//! section is capped at 9,999,999 lines). Each file is replaced atomically, its writeback to
//! disk started as it is written ([`write_atomically_streamed`]), so the fsync that ends it is
//! short.
//!
//! Layer 3 (session): depends on [`crate::iges`], [`crate::nurbs`] and [`crate::atomic`].

use crate::atomic::write_atomically_streamed;
use crate::iges::{plan_layout, write_iges_seekable, IgesError, IgesOptions};
use crate::nurbs::NurbsSurface;
use std::path::{Path, PathBuf};

/// Where part `index` (1-based) of `count` goes when the surface needs several files:
/// `dir/name.igs` → `dir/name.part2-of-3.igs` (an output without extension gets
/// `.part2-of-3`).
pub fn part_path(output: &Path, index: usize, count: usize) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match output.extension() {
        Some(ext) => format!("{stem}.part{index}-of-{count}.{}", ext.to_string_lossy()),
        None => format!("{stem}.part{index}-of-{count}"),
    };
    output.with_file_name(name)
}

/// The v parameter range covered by a group of consecutive patches.
fn v_range(patches: &[NurbsSurface]) -> [f64; 2] {
    let lo = patches
        .first()
        .and_then(|s| s.knots_v().get(s.degree_v()).copied())
        .unwrap_or(f64::NAN);
    let hi = patches
        .last()
        .and_then(|s| s.knots_v().get(s.count_v()).copied())
        .unwrap_or(f64::NAN);
    [lo, hi]
}

/// One IGES file written by [`write_surface_files`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WrittenIges {
    /// Path.
    pub path: PathBuf,
    /// 1-based part number.
    pub part: usize,
    /// v parameter range of the part.
    pub v_range: [f64; 2],
    /// Entities 128 in it.
    pub patches: usize,
    /// Bytes.
    pub bytes: u64,
    /// Parameter Data lines.
    pub parameter_lines: usize,
}

/// Why the IGES files could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SurfaceWriteError {
    /// The surface cannot be represented in the format (a data problem).
    #[error("cannot write IGES {path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What the writer refused.
        message: String,
    },
    /// The file system refused (full disk, permissions).
    #[error("cannot write IGES {path}: {source}; {}", crate::atomic::write_hint(.path, .source))]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

fn write_error(path: &Path, e: std::io::Error) -> SurfaceWriteError {
    let format = e
        .get_ref()
        .and_then(|inner| inner.downcast_ref::<IgesError>())
        .filter(|ie| !matches!(ie, IgesError::Io(_)))
        .map(|ie| ie.to_string());
    match format {
        Some(message) => SurfaceWriteError::Format {
            path: path.to_path_buf(),
            message,
        },
        None => SurfaceWriteError::Io {
            path: path.to_path_buf(),
            source: e,
        },
    }
}

/// Writes `surface` as IGES at `output`, or as several complete files
/// `output.part<i>-of-<n>.igs` when one P section cannot hold it; each file atomically.
/// Errors carry the path and say whether the format or the disk refused.
pub fn write_surface_files(
    output: &Path,
    surface: &NurbsSurface,
    opts: &IgesOptions,
) -> Result<Vec<WrittenIges>, SurfaceWriteError> {
    let format_error = |e: IgesError| SurfaceWriteError::Format {
        path: output.to_path_buf(),
        message: e.to_string(),
    };
    // Each file's patches are built just before it is written and freed after.
    let plan = plan_layout(surface, opts).map_err(format_error)?;
    let n_files = plan.len();
    let mut files = Vec::with_capacity(n_files);
    for k in 0..n_files {
        let group = plan.part(k).map_err(format_error)?;
        let group = &group[..];
        let range = v_range(group);
        let path = if n_files == 1 {
            output.to_path_buf()
        } else {
            part_path(output, k + 1, n_files)
        };
        let mut part_opts = opts.clone();
        part_opts.file_name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if n_files > 1 {
            part_opts.start_lines.push(format!(
                "part {} of {}, v range [{}, {}]; {} exact patch(es); adjacent parts share their boundary pole row, the union of all parts is the surface.",
                k + 1,
                n_files,
                range[0],
                range[1],
                group.len()
            ));
        }
        let st = write_atomically_streamed(&path, |w| {
            write_iges_seekable(w, group, &part_opts).map_err(std::io::Error::other)
        })
        .map_err(|e| write_error(&path, e))?;
        files.push(WrittenIges {
            path,
            part: k + 1,
            v_range: range,
            patches: st.patches,
            bytes: st.bytes,
            parameter_lines: st.parameter_lines,
        });
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_names_keep_directory_and_extension() {
        assert_eq!(
            part_path(Path::new("/data/run 7/sur-2.igs"), 2, 3),
            PathBuf::from("/data/run 7/sur-2.part2-of-3.igs")
        );
        assert_eq!(
            part_path(Path::new("out/a.b.IGES"), 10, 12),
            PathBuf::from("out/a.b.part10-of-12.IGES")
        );
        assert_eq!(
            part_path(Path::new("surface"), 1, 2),
            PathBuf::from("surface.part1-of-2")
        );
    }
}
