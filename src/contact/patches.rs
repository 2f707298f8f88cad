//! Contact patches: the connected regions of the contact, counted with 4-connectivity (two
//! points in contact belong to one patch when they are neighbours along x or along y;
//! diagonal neighbours do not join, as in contact.engineering's patch count). The grid is not
//! periodic: a patch never wraps around an edge.
//!
//! Layer 1 (pure logic): depends on nothing else in the crate.

/// Sizes of the patches of a `rows × cols` contact mask (row-major), and how many rows each
/// spans.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Patches {
    /// Points in each patch.
    pub sizes: Vec<usize>,
    /// Rows (lines) each patch spans, in the same order.
    pub row_spans: Vec<usize>,
}

impl Patches {
    /// Number of patches.
    pub fn count(&self) -> usize {
        self.sizes.len()
    }

    /// Fraction of the contact points that form a patch of one point (0 without contact).
    pub fn single_point_fraction(&self) -> f64 {
        let total: usize = self.sizes.iter().sum();
        let single = self.sizes.iter().filter(|&&s| s == 1).count();
        if total == 0 {
            0.0
        } else {
            single as f64 / total as f64
        }
    }

    /// Fraction of the contact points in patches that lie on a single row (0 without
    /// contact): how much of the contact is not resolved across the lines.
    pub fn single_row_fraction(&self) -> f64 {
        let total: usize = self.sizes.iter().sum();
        let on_one: usize = self
            .sizes
            .iter()
            .zip(&self.row_spans)
            .filter(|(_, &r)| r == 1)
            .map(|(s, _)| s)
            .sum();
        if total == 0 {
            0.0
        } else {
            on_one as f64 / total as f64
        }
    }
}

/// The patches of `mask` (`true` = in contact), flood-filled with an explicit stack (no
/// recursion, so a patch of a million points cannot overflow the call stack).
pub fn patches(mask: &[bool], rows: usize, cols: usize) -> Patches {
    assert_eq!(mask.len(), rows * cols, "mask must cover the grid");
    let mut seen = vec![false; mask.len()];
    let mut stack = Vec::new();
    let mut out = Patches::default();
    for start in 0..mask.len() {
        if !mask[start] || seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut size, mut row_lo, mut row_hi) = (0, start / cols, start / cols);
        while let Some(i) = stack.pop() {
            size += 1;
            let (r, c) = (i / cols, i % cols);
            row_lo = row_lo.min(r);
            row_hi = row_hi.max(r);
            let mut visit = |j: usize| {
                if mask[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if c > 0 {
                visit(i - 1);
            }
            if c + 1 < cols {
                visit(i + 1);
            }
            if r > 0 {
                visit(i - cols);
            }
            if r + 1 < rows {
                visit(i + cols);
            }
        }
        out.sizes.push(size);
        out.row_spans.push(row_hi - row_lo + 1);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(rows: &[&str]) -> (Vec<bool>, usize, usize) {
        let cols = rows[0].len();
        let m = rows
            .iter()
            .flat_map(|r| r.chars().map(|c| c == '#'))
            .collect();
        (m, rows.len(), cols)
    }

    #[test]
    fn diagonal_neighbours_are_separate_patches_and_edges_do_not_wrap() {
        let (m, r, c) = mask(&[
            "#..##", //
            ".#..#", //
            "....#", //
            "#.#..", //
        ]);
        let p = patches(&m, r, c);
        // {0,0}; {1,1}; {0,3},{0,4},{1,4},{2,4}; {3,0}; {3,2}: the right column does not
        // wrap onto the left one.
        let mut sizes = p.sizes.clone();
        sizes.sort();
        assert_eq!(sizes, vec![1, 1, 1, 1, 4]);
        assert_eq!(p.count(), 5);
        assert!((p.single_point_fraction() - 4.0 / 8.0).abs() < 1e-15);
        // Only the 4-point patch spans more than one row.
        assert!((p.single_row_fraction() - 4.0 / 8.0).abs() < 1e-15);
    }

    #[test]
    fn no_contact_no_patches() {
        let p = patches(&[false; 6], 2, 3);
        assert_eq!(p.count(), 0);
        assert_eq!(p.single_point_fraction(), 0.0);
    }

    #[test]
    fn a_ring_is_one_patch() {
        let (m, r, c) = mask(&["####", "#..#", "####"]);
        assert_eq!(patches(&m, r, c).sizes, vec![10]);
    }
}
