//! The control net of a [`super::NurbsSurface`], held compactly where its coordinates repeat.
//!
//! A fitted net's x depends on the column alone and its y on the row alone (x is the 1-D solve
//! along u of the data's x, y the 1-D solve along v of the lines' y), so the net keeps z per
//! pole, x per column and y per row: a third of the memory of three coordinates per pole. A
//! row whose x differs from the column x in any bit (a row blended by knot insertion, a net
//! read from a file) keeps its own x; a row whose y is not one value keeps its own y. Every
//! pole reads back as the same bits it was built from, whatever the layout.
//!
//! Layer 0 (vocabulary): depends on nothing else in the crate; no I/O.

/// The y of one pole row: one value for the whole row, or one per pole.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RowY<'a> {
    /// Every pole of the row has this y.
    One(f64),
    /// The y of each pole.
    Each(&'a [f64]),
}

impl RowY<'_> {
    /// The y of pole `i` of the row.
    #[inline(always)]
    pub fn at(&self, i: usize) -> f64 {
        match *self {
            RowY::One(y) => y,
            RowY::Each(ys) => ys[i],
        }
    }
}

/// One row of poles (fixed v index), u along the row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoleRow<'a> {
    /// x of each pole.
    pub x: &'a [f64],
    /// y of the row's poles.
    pub y: RowY<'a>,
    /// z of each pole.
    pub z: &'a [f64],
}

impl PoleRow<'_> {
    /// Number of poles in the row.
    pub fn len(&self) -> usize {
        self.z.len()
    }

    /// Whether the row is empty.
    pub fn is_empty(&self) -> bool {
        self.z.is_empty()
    }

    /// Pole `i` of the row.
    #[inline(always)]
    pub fn get(&self, i: usize) -> [f64; 3] {
        [self.x[i], self.y.at(i), self.z[i]]
    }
}

/// The poles of a net, v-outer / u-inner (pole (i, j) at `j * count_u + i`).
#[derive(Debug, Clone, Default)]
pub struct PoleNet {
    count_u: usize,
    /// x per column, for every row without its own.
    x: Vec<f64>,
    /// Per row: its own x, when it differs from `x` in any bit.
    own_x: Vec<Option<Vec<f64>>>,
    /// y per row (the row's y when it is one value).
    y: Vec<f64>,
    /// Per row: its own y per pole, when the row's y is not one value.
    own_y: Vec<Option<Vec<f64>>>,
    /// z per pole.
    z: Vec<f64>,
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits())
}

impl PoleNet {
    /// An empty net of rows `count_u` poles long whose rows share the column x `x`
    /// (`x.len() == count_u`); rows are added with [`PoleNet::push_row`].
    pub fn with_columns(x: Vec<f64>, rows: usize) -> PoleNet {
        let count_u = x.len();
        PoleNet {
            count_u,
            x,
            own_x: Vec::with_capacity(rows),
            y: Vec::with_capacity(rows),
            own_y: Vec::with_capacity(rows),
            z: Vec::with_capacity(rows.saturating_mul(count_u)),
        }
    }

    /// A net whose x depends on the column alone and y on the row alone: pole (i, j) is
    /// `[x[i], y[j], z[j * x.len() + i]]`. `None` when `z` is not `x.len() × y.len()` values.
    pub fn separable(x: Vec<f64>, y: Vec<f64>, z: Vec<f64>) -> Option<PoleNet> {
        if z.len() != x.len().checked_mul(y.len())? {
            return None;
        }
        let rows = y.len();
        Some(PoleNet {
            count_u: x.len(),
            x,
            own_x: vec![None; rows],
            y,
            own_y: vec![None; rows],
            z,
        })
    }

    /// The net of `poles` (v-outer, rows of `count_u`; a partial last row is dropped), laid
    /// out compactly where its coordinates repeat.
    pub fn from_poles(count_u: usize, poles: &[[f64; 3]]) -> PoleNet {
        if count_u == 0 {
            return PoleNet::default();
        }
        let rows = poles.len() / count_u;
        let x0: Vec<f64> = poles.iter().take(count_u).map(|p| p[0]).collect();
        let mut net = PoleNet::with_columns(x0, rows);
        for row in poles.chunks_exact(count_u) {
            net.push_poles(row);
        }
        net
    }

    /// Appends a row given as three coordinates per pole (see [`PoleNet::push_row`]).
    pub fn push_poles(&mut self, row: &[[f64; 3]]) {
        let x: Vec<f64> = row.iter().map(|p| p[0]).collect();
        let y: Vec<f64> = row.iter().map(|p| p[1]).collect();
        let z: Vec<f64> = row.iter().map(|p| p[2]).collect();
        self.push_row(PoleRow {
            x: &x,
            y: RowY::Each(&y),
            z: &z,
        });
    }

    /// Appends a row (`row.len()` must be the net's row length; a row of another length is
    /// ignored). Its x is kept only if it differs from the column x, its y only if the row's
    /// y is not one value (bits compared).
    pub fn push_row(&mut self, row: PoleRow<'_>) {
        if row.x.len() != self.count_u || row.z.len() != self.count_u {
            return;
        }
        if let RowY::Each(ys) = row.y {
            if ys.len() != self.count_u {
                return;
            }
        }
        self.own_x
            .push((!same_bits(row.x, &self.x)).then(|| row.x.to_vec()));
        match row.y {
            RowY::One(y) => {
                self.y.push(y);
                self.own_y.push(None);
            }
            RowY::Each(ys) => {
                let first = ys.first().copied().unwrap_or(0.0);
                self.y.push(first);
                let one = ys.iter().all(|v| v.to_bits() == first.to_bits());
                self.own_y.push((!one).then(|| ys.to_vec()));
            }
        }
        self.z.extend_from_slice(row.z);
    }

    /// Poles along u (the row length).
    pub fn count_u(&self) -> usize {
        self.count_u
    }

    /// Pole rows along v.
    pub fn count_v(&self) -> usize {
        self.y.len()
    }

    /// Number of poles.
    pub fn len(&self) -> usize {
        self.z.len()
    }

    /// Whether the net has no poles.
    pub fn is_empty(&self) -> bool {
        self.z.is_empty()
    }

    /// Row `j` (panics past the last row).
    #[inline(always)]
    pub fn row(&self, j: usize) -> PoleRow<'_> {
        let nu = self.count_u;
        PoleRow {
            x: self.own_x[j].as_deref().unwrap_or(&self.x),
            y: match &self.own_y[j] {
                Some(ys) => RowY::Each(ys),
                None => RowY::One(self.y[j]),
            },
            z: &self.z[j * nu..(j + 1) * nu],
        }
    }

    /// Pole (i along u, j along v).
    #[inline(always)]
    pub fn pole(&self, i: usize, j: usize) -> [f64; 3] {
        self.row(j).get(i)
    }

    /// Pole number `k` in v-outer / u-inner order.
    pub fn pole_at(&self, k: usize) -> [f64; 3] {
        self.pole(k % self.count_u, k / self.count_u)
    }

    /// The rows, in v order.
    pub fn rows(&self) -> impl ExactSizeIterator<Item = PoleRow<'_>> + Clone + '_ {
        (0..self.count_v()).map(|j| self.row(j))
    }

    /// Every pole in v-outer / u-inner order.
    pub fn iter(&self) -> Poles<'_> {
        Poles {
            net: self,
            next: 0,
            end: self.len(),
        }
    }

    /// The poles numbered `range` (v-outer / u-inner) appended to `out` as three coordinates
    /// each.
    pub fn extend_poles(&self, range: std::ops::Range<usize>, out: &mut Vec<[f64; 3]>) {
        let nu = self.count_u.max(1);
        let end = range.end.min(self.len());
        let mut k = range.start.min(end);
        out.reserve(end - k);
        while k < end {
            let (j, i0) = (k / nu, k % nu);
            let i1 = (i0 + end - k).min(nu);
            let row = self.row(j);
            out.extend((i0..i1).map(|i| row.get(i)));
            k += i1 - i0;
        }
    }

    /// Every pole as three coordinates (the full net's memory; for tests and small nets).
    pub fn to_vec(&self) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        self.extend_poles(0..self.len(), &mut out);
        out
    }

    /// Every pole moved by `dx` along x.
    pub fn shift_x(&mut self, dx: f64) {
        let own = self.own_x.iter_mut().flatten().flatten();
        self.x.iter_mut().chain(own).for_each(|x| *x += dx);
    }

    /// The x per column that rows without their own x share.
    pub fn column_x(&self) -> &[f64] {
        &self.x
    }

    /// Whether no row keeps its own x or y: x depends on the column alone, y on the row.
    pub fn is_separable(&self) -> bool {
        self.own_x.iter().all(Option::is_none) && self.own_y.iter().all(Option::is_none)
    }
}

/// Nets are equal when every pole compares equal, whatever their layout.
impl PartialEq for PoleNet {
    fn eq(&self, other: &PoleNet) -> bool {
        self.count_u == other.count_u
            && self.count_v() == other.count_v()
            && self.rows().zip(other.rows()).all(|(a, b)| {
                a.x == b.x && a.z == b.z && (0..a.len()).all(|i| a.y.at(i) == b.y.at(i))
            })
    }
}

/// The poles of a [`PoleNet`] in v-outer / u-inner order ([`PoleNet::iter`]).
#[derive(Debug, Clone)]
pub struct Poles<'a> {
    net: &'a PoleNet,
    next: usize,
    end: usize,
}

impl Iterator for Poles<'_> {
    type Item = [f64; 3];

    #[inline]
    fn next(&mut self) -> Option<[f64; 3]> {
        if self.next >= self.end {
            return None;
        }
        let p = self.net.pole_at(self.next);
        self.next += 1;
        Some(p)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.end - self.next;
        (n, Some(n))
    }
}

impl ExactSizeIterator for Poles<'_> {}

#[cfg(test)]
mod tests {
    use super::*;

    fn bits(v: &[[f64; 3]]) -> Vec<[u64; 3]> {
        v.iter().map(|p| p.map(f64::to_bits)).collect()
    }

    #[test]
    fn a_separable_net_reads_back_every_pole_it_was_given() {
        let x = vec![0.0, 0.1, 0.30000000000000004];
        let y = vec![-0.0, 0.02];
        let z: Vec<f64> = (0..6).map(|k| k as f64 * 1e-3 - 2e-3).collect();
        let net = PoleNet::separable(x.clone(), y.clone(), z.clone()).unwrap();
        assert!(net.is_separable());
        let full: Vec<[f64; 3]> = (0..2)
            .flat_map(|j| (0..3).map(move |i| (i, j)))
            .map(|(i, j)| [x[i], y[j], z[j * 3 + i]])
            .collect();
        assert_eq!(bits(&net.to_vec()), bits(&full));
        assert_eq!(bits(&net.iter().collect::<Vec<_>>()), bits(&full));
        assert_eq!(net.pole(2, 1).map(f64::to_bits), full[5].map(f64::to_bits));
        assert!(PoleNet::separable(x, y, z[..5].to_vec()).is_none());
    }

    #[test]
    fn a_net_that_is_not_separable_keeps_every_bit() {
        // Row 1's x differs from row 0's in the last bit (as a blended row's may), row 2's y
        // varies along the row, and a -0.0 beside 0.0 differs only in its sign bit.
        let nu = 3;
        let mut poles = Vec::new();
        for j in 0..4 {
            for i in 0..nu {
                let mut x = i as f64 * 0.1;
                if j == 1 && i == 2 {
                    x = f64::from_bits(x.to_bits() + 1);
                }
                let y = if j == 2 {
                    0.5 + i as f64 * 1e-17
                } else {
                    j as f64
                };
                let x = if j == 3 && i == 0 { -0.0 } else { x };
                poles.push([x, y, (i * 7 + j) as f64 * 0.25]);
            }
        }
        let net = PoleNet::from_poles(nu, &poles);
        assert!(!net.is_separable());
        assert_eq!(bits(&net.to_vec()), bits(&poles));
        assert_eq!(bits(&net.iter().collect::<Vec<_>>()), bits(&poles));
        for (k, p) in poles.iter().enumerate() {
            assert_eq!(
                net.pole_at(k).map(f64::to_bits),
                p.map(f64::to_bits),
                "pole {k}"
            );
        }
        let mut part = Vec::new();
        net.extend_poles(2..10, &mut part);
        assert_eq!(bits(&part), bits(&poles[2..10]));
    }

    #[test]
    fn nets_compare_by_their_poles_not_their_layout() {
        let poles: Vec<[f64; 3]> = (0..6)
            .map(|k| [(k % 3) as f64, (k / 3) as f64, k as f64])
            .collect();
        let compact = PoleNet::from_poles(3, &poles);
        let mut built = PoleNet::with_columns(vec![9.0, 9.0, 9.0], 2);
        for row in poles.chunks_exact(3) {
            built.push_poles(row);
        }
        assert!(compact.is_separable() && !built.is_separable());
        assert_eq!(compact, built);
        let mut other = poles.clone();
        other[4][1] = 1.5;
        assert_ne!(compact, PoleNet::from_poles(3, &other));
    }
}
