//! The rows of a grid CSV: one row of heights per line, in the layout [`super::text`] found.
//!
//! One policy for a row that cannot be used: a value that is not a number, a height that is
//! not finite (NaN, as some software writes for a point not measured), one beyond any surface
//! ([`MAX_HEIGHT_UM`]: a file in other units or a damaged digit), or a number of points unlike
//! the other rows' (the rows' length is the one most rows have, the first such on a tie) —
//! the row is left out and named with its line in the file and why, and the other rows keep
//! their place (their y). Nothing is filled in. An error only when no row can be used.
//!
//! A large file is read as two runs of whole lines on two threads, each writing its values
//! into its own part of the one buffer the grid keeps; the rows, the values and what is left
//! out are those of reading it line by line.
//!
//! Pure (no I/O), inside the reading layer: text in, values out; depends on [`crate::numbers`] and the metrology's
//! height bound.

use super::text::{Dialect, Layout};
use crate::metrology::MAX_HEIGHT_UM;

/// The rows of a grid CSV as read.
#[derive(Debug, Clone, PartialEq)]
pub struct Rows {
    /// Heights in µm of the rows kept, row-major.
    pub heights_um: Vec<f64>,
    /// Points per row.
    pub cols: usize,
    /// 0-based place of each kept row among the file's rows (its y is this × the y pitch).
    pub kept: Vec<usize>,
    /// Each row left out: its 0-based place among the rows, its 1-based line in the file and
    /// why.
    pub left_out: Vec<(usize, usize, String)>,
}

/// Files of at least this many bytes are read in two halves side by side.
pub const PARALLEL_BYTES: usize = 256 << 10;

/// One row as read: its 0-based line in the file, and how many values it wrote or why it
/// cannot be used.
type RowRead = (usize, Result<usize, String>);

/// Reads the rows of `text` (laid out as `layout` says) in µm (`um_per_unit` µm per unit of
/// the file), in two runs on two threads when it has at least `parallel_bytes` bytes. Both
/// runs write into one buffer with room for every value, the second run's part right after
/// the first's, so the values of a file whose rows are all kept are in place when the runs
/// end: nothing is copied, and no page is touched twice. The text is dropped before the
/// rows left out (if any) are compacted.
pub fn read_rows(
    text: String,
    layout: &Layout,
    um_per_unit: f64,
    parallel_bytes: usize,
) -> Result<Rows, String> {
    let (values, first, second) = {
        let lines: Vec<(usize, &str)> = text
            .lines()
            .enumerate()
            .skip(layout.data_from)
            .filter(|(_, l)| !l.trim().is_empty())
            .collect();
        // The second run starts at the first line past the middle byte.
        let split = if text.len() >= parallel_bytes && lines.len() >= 2 {
            let mut bytes = 0usize;
            lines
                .iter()
                .position(|(_, l)| {
                    bytes += l.len() + 1;
                    bytes >= text.len() / 2
                })
                .map_or(lines.len(), |i| (i + 1).min(lines.len()))
        } else {
            lines.len()
        };
        let (head, tail) = lines.split_at(split);
        // Room for every value: a line holds at most one more than its separators.
        let sep = layout.dialect.separator;
        let room = |ls: &[(usize, &str)]| -> usize {
            ls.iter()
                .map(|(_, l)| count_byte(l.as_bytes(), sep) + 1)
                .sum()
        };
        let head_room = room(head);
        // Zeroed by the allocator (fresh pages for a large grid): no page is touched before
        // a run writes its values there.
        let mut values = vec![0.0; head_room + room(tail)];
        let read = |ls: &[(usize, &str)], out: &mut [f64]| -> Vec<RowRead> {
            let mut at = 0;
            ls.iter()
                .map(|&(n, line)| {
                    let room = out.get_mut(at..).unwrap_or_default();
                    let r = read_row(line, &layout.dialect, um_per_unit, room);
                    at += r.as_ref().map_or(0, |count| *count);
                    (n, r)
                })
                .collect()
        };
        let (head_out, tail_out) = values.split_at_mut(head_room);
        let (first, second) = if tail.is_empty() {
            (read(head, head_out), None)
        } else {
            std::thread::scope(|s| {
                let second = s.spawn(|| read(tail, tail_out));
                let first = read(head, head_out);
                let second = second
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
                (first, Some(second))
            })
        };
        (values, first, second.map(|rows| (head_room, rows)))
    };
    drop(text);
    join(values, first, second)
}

/// How many times `byte` occurs in `bytes`: counted in one-byte lanes, 255 bytes at a time
/// (no lane can overflow), which the compiler turns into wide compares: about ten times
/// faster than adding each comparison to a `usize`.
fn count_byte(bytes: &[u8], byte: u8) -> usize {
    bytes
        .chunks(255)
        .map(|c| usize::from(c.iter().fold(0u8, |n, &b| n + u8::from(b == byte))))
        .sum()
}

/// The rows of both runs (the second's values from `second.0` in `values`): the rows' length
/// decided, the rows of another length left out, the kept values moved down in file order
/// (where a row before them was left out, or the first run wrote less than its room).
fn join(
    mut values: Vec<f64>,
    first: Vec<RowRead>,
    second: Option<(usize, Vec<RowRead>)>,
) -> Result<Rows, String> {
    let runs: Vec<(usize, &[RowRead])> = std::iter::once((0, &first[..]))
        .chain(second.as_ref().map(|(at, rows)| (*at, &rows[..])))
        .collect();
    // The rows' length: the most common, the first such on a tie.
    let mut counts: std::collections::HashMap<usize, (usize, usize)> = Default::default();
    let all_rows = || runs.iter().flat_map(|(_, rows)| rows.iter());
    for (at, (_, r)) in all_rows().enumerate() {
        if let Ok(c) = r {
            counts.entry(*c).or_insert((0, at)).0 += 1;
        }
    }
    let cols = counts
        .iter()
        .max_by_key(|(_, &(times, first))| (times, std::cmp::Reverse(first)))
        .map(|(&len, _)| len);
    let Some(cols) = cols else {
        return Err(
            match all_rows().find_map(|(l, r)| r.as_ref().err().map(|w| (l, w))) {
                None => "the file holds no rows of heights".to_string(),
                Some((line, why)) => {
                    format!("no row can be used; the first, line {} ({why})", line + 1)
                }
            },
        );
    };
    let mut out = Rows {
        heights_um: Vec::new(),
        cols,
        kept: Vec::new(),
        left_out: Vec::new(),
    };
    let (mut kept, mut place) = (0usize, 0usize);
    for &(from, rows) in &runs {
        let mut start = from;
        for (line, r) in rows {
            if out.take(place, *line, r, cols).is_some() {
                if start != kept {
                    values.copy_within(start..start + cols, kept);
                }
                kept += cols;
            }
            start += r.as_ref().map_or(0, |count| *count);
            place += 1;
        }
    }
    values.truncate(kept);
    out.heights_um = values;
    Ok(out)
}

impl Rows {
    /// Records the row at `place` (0-based line `line` of the file, read as `r`) as kept
    /// (returning its length) or left out with why.
    fn take(
        &mut self,
        place: usize,
        line: usize,
        r: &Result<usize, String>,
        cols: usize,
    ) -> Option<usize> {
        match r {
            Ok(count) if *count == cols => {
                self.kept.push(place);
                Some(cols)
            }
            Ok(count) => {
                self.left_out.push((
                    place,
                    line + 1,
                    format!("it has {count} values where the rows have {cols}"),
                ));
                None
            }
            Err(why) => {
                self.left_out.push((place, line + 1, why.clone()));
                None
            }
        }
    }
}

/// Writes the heights of one row (`line`, read as `dialect` says, scaled by `um_per_unit`)
/// to the front of `out` (room for one more than the line's separators) and returns how
/// many, or why the row cannot be used (what it wrote then counts for nothing).
fn read_row(
    line: &str,
    dialect: &Dialect,
    um_per_unit: f64,
    out: &mut [f64],
) -> Result<usize, String> {
    // Plain lines of finite numbers take one pass; anything else field by field.
    let fast = match *dialect == Dialect::PLAIN {
        true => crate::numbers::parse_csv_line(line.as_bytes(), out),
        false => None,
    };
    let count = match fast {
        Some(count) => count,
        None => {
            let fields = dialect.fields(line);
            for (k, f) in fields.iter().enumerate() {
                match (dialect.number(f), out.get_mut(k)) {
                    (Some(v), Some(slot)) => *slot = v,
                    (Some(_), None) => {
                        return Err(format!(
                            "more values than the {} it has room for",
                            out.len()
                        ))
                    }
                    (None, _) => return Err(format!("column {}: {f:?} is not a number", k + 1)),
                }
            }
            fields.len()
        }
    };
    let values = &mut out[..count];
    if um_per_unit != 1.0 {
        values.iter_mut().for_each(|v| *v *= um_per_unit);
    }
    let not_finite = values.iter().filter(|v| !v.is_finite()).count();
    // A height beyond any surface (a value in other units, a damaged digit) leaves its row
    // out as a NaN does, instead of ending the reading of every row.
    let beyond = values
        .iter()
        .filter(|v| v.is_finite() && v.abs() > MAX_HEIGHT_UM)
        .count();
    let why = if not_finite > 0 {
        format!("{not_finite} of its {count} heights are not finite: NaN or infinite, not measured")
    } else if beyond > 0 {
        format!("{beyond} of its {count} heights are beyond ±{MAX_HEIGHT_UM:e} µm, no surface height: check the units")
    } else {
        return Ok(count);
    };
    Err(why)
}

#[cfg(test)]
mod tests {
    use super::super::text::layout;
    use super::*;

    fn rows_of(text: &str, parallel_bytes: usize) -> Result<Rows, String> {
        let l = layout(text)?;
        read_rows(text.to_string(), &l, 1.0, parallel_bytes)
    }

    fn rows(text: &str) -> Result<Rows, String> {
        rows_of(text, usize::MAX)
    }

    #[test]
    fn a_grid_is_read_with_its_header_and_blank_lines_skipped() {
        let g = rows("a,b,c\n1,2,3\n\n4.5,-6e-1,+7\n\n").unwrap();
        assert_eq!(g.heights_um, vec![1.0, 2.0, 3.0, 4.5, -0.6, 7.0]);
        assert_eq!((g.cols, g.kept.clone()), (3, vec![0, 1]));
        assert!(g.left_out.is_empty());
    }

    #[test]
    fn damaged_rows_are_left_out_and_named_and_the_others_keep_their_place() {
        let text = "1,2,3,4\n1,2,x,4\n1,2,3\n1,NaN,3,inf\n5,6,7,8\n1,2e9,3,-4e12\n\n9,10,11,12\n";
        let g = rows(text).unwrap();
        assert_eq!(g.cols, 4);
        assert_eq!(g.kept, vec![0, 4, 6], "rows keep their place in the file");
        assert_eq!(
            g.heights_um,
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0]
        );
        let left: Vec<(usize, usize)> = g.left_out.iter().map(|(p, l, _)| (*p, *l)).collect();
        assert_eq!(left, vec![(1, 2), (2, 3), (3, 4), (5, 6)]);
        let why: Vec<&str> = g.left_out.iter().map(|(_, _, w)| w.as_str()).collect();
        assert_eq!(why[0], "column 3: \"x\" is not a number");
        assert_eq!(why[1], "it has 3 values where the rows have 4");
        assert!(
            why[2].starts_with("2 of its 4 heights are not finite"),
            "{}",
            why[2]
        );
        assert!(
            why[3].starts_with("2 of its 4 heights are beyond ±1e9 µm"),
            "{}",
            why[3]
        );
    }

    #[test]
    fn the_rows_length_is_the_one_most_rows_have() {
        // A short first row does not make every full row wrong.
        let g = rows("1,2\n1,2,3\n4,5,6\n7,8,9\n").unwrap();
        assert_eq!((g.cols, g.kept.clone()), (3, vec![1, 2, 3]));
        assert_eq!(g.left_out.len(), 1);
        // On a tie, the first length.
        let g = rows("1,2\n1,2,3\n").unwrap();
        assert_eq!((g.cols, g.kept.clone()), (2, vec![0]));
    }

    #[test]
    fn a_grid_with_no_usable_row_is_an_error_naming_the_first() {
        let e = rows("x_um,y_um\n2,y\n3,NaN\n").unwrap_err();
        assert_eq!(
            e,
            "no row can be used; the first, line 2 (column 2: \"y\" is not a number)"
        );
        assert_eq!(
            rows("x_um,y_um\n\n").unwrap_err(),
            "the file holds no rows of heights"
        );
        assert_eq!(rows("").unwrap_err(), "the file holds no rows of heights");
    }

    #[test]
    fn units_scale_the_heights_and_their_bound() {
        let l = layout("1,2\n3e9,4\n5,6\n").unwrap();
        let g = read_rows("1,2\n3e9,4\n5,6\n".into(), &l, 1e-3, usize::MAX).unwrap();
        // 3e9 nm is 3 m: a height in nm, not beyond any surface.
        assert_eq!(g.heights_um, vec![1e-3, 2e-3, 3e6, 4e-3, 5e-3, 6e-3]);
        let g = read_rows("1,2\n3e9,4\n5,6\n".into(), &l, 1.0, usize::MAX).unwrap();
        assert_eq!(g.kept, vec![0, 2]);
    }

    #[test]
    fn semicolons_tabs_and_decimal_commas_are_read() {
        let g = rows("z [um];z [um]\n1,5;-2,25\n3;4\n").unwrap();
        assert_eq!(g.heights_um, vec![1.5, -2.25, 3.0, 4.0]);
        let g = rows("1.5\t2\n3\t4,5\n").unwrap();
        assert_eq!(g.heights_um, vec![1.5, 2.0, 3.0, 4.5]);
    }

    /// Random grids of good and damaged rows, read in one run and in two: the same rows,
    /// values and rows left out as a plain reading of the same lines.
    #[test]
    fn random_damaged_grids_keep_exactly_the_usable_rows_in_one_run_or_two() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: u64| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) % n
        };
        for case in 0..2000 {
            let mut lines: Vec<String> = Vec::new();
            let header = next(4) == 0;
            if header {
                lines.push("z_um,z_um,z_um".into());
            }
            for _ in 0..next(9) {
                let len = 3 + next(3) as usize;
                let mut fields: Vec<String> = (0..len)
                    .map(|_| format!("{}", next(2001) as f64 / 100.0 - 10.0))
                    .collect();
                match next(8) {
                    0 => fields[next(len as u64) as usize] = "1.2.3".into(),
                    1 => fields[next(len as u64) as usize] = "NaN".into(),
                    2 => fields = vec![String::new()],
                    3 => fields[0] = format!(" {} ", fields[0]),
                    _ => {}
                }
                lines.push(fields.join(","));
            }
            let text = lines.join("\n");
            // The plain reading: each non-blank line after the header is a row.
            let mut plain: Vec<Option<Vec<f64>>> = Vec::new();
            for (n, l) in text.lines().enumerate() {
                if l.trim().is_empty() || (header && n == 0) {
                    continue;
                }
                let v: Result<Vec<f64>, _> = l.split(',').map(|f| f.trim().parse()).collect();
                match v {
                    Ok(v) if v.iter().all(|x: &f64| x.is_finite()) => plain.push(Some(v)),
                    _ => plain.push(None),
                }
            }
            let lens: Vec<usize> = plain.iter().flatten().map(Vec::len).collect();
            let cols = lens.iter().copied().max_by_key(|&c| {
                let first = lens.iter().position(|&x| x == c).unwrap();
                (lens.iter().filter(|&&x| x == c).count(), usize::MAX - first)
            });
            let serial = rows_of(&text, usize::MAX);
            assert_eq!(rows_of(&text, 0), serial, "case {case}: {text:?}");
            let Some(cols) = cols else {
                assert!(serial.is_err(), "case {case}: {text:?}");
                continue;
            };
            let g = serial.unwrap_or_else(|e| panic!("case {case}: {e}: {text:?}"));
            let kept: Vec<usize> = (0..plain.len())
                .filter(|&r| plain[r].as_ref().is_some_and(|v| v.len() == cols))
                .collect();
            assert_eq!((g.cols, &g.kept), (cols, &kept), "case {case}: {text:?}");
            let heights: Vec<f64> = kept
                .iter()
                .flat_map(|&r| plain[r].clone().unwrap())
                .collect();
            assert_eq!(g.heights_um, heights, "case {case}: {text:?}");
            assert_eq!(g.left_out.len(), plain.len() - kept.len(), "case {case}");
        }
    }
}
