//! The elastic half-space under a grid of pixel pressures, non-periodic: displacements
//! `u = K p` as a linear convolution of the pressures with the pixel influence coefficients
//! ([`super::influence`]), evaluated with FFTs on a zero-padded grid (Hockney 1970).
//!
//! A grid of `rows × cols` pixels needs the kernel at offsets −(n−1)…n−1 along each axis, so
//! the convolution runs on a padded grid of at least 2n − 1 points per axis; the size is
//! rounded up to a product of 2, 3 and 5, which changes nothing in the result (the kernel
//! entries beyond ±(n−1) are zero and never reach a grid point) and keeps the FFTs fast.
//! The kernel is even in x and y, so its transform is real and stored as such.
//!
//! The transform runs along x with real FFTs over the `rows` rows that carry pressure (the
//! padding rows are zero and skipped), then along y per frequency column, where it is
//! multiplied by the kernel's transform and inverted at once; the inverse along x is taken
//! only for the `rows` rows whose displacements are wanted. Working memory is one complex
//! value per padded-grid point along y times half the padded x size, plus the kernel's real
//! transform of the same shape: about 1.5 × the padded grid in f64.
//!
//! Units are the caller's: lateral pitches and the result in one length unit (µm in this
//! module's users), pressures and the modulus in one pressure unit (MPa).
//!
//! Layer 1 (pure logic): depends on [`super::influence`] and the FFT crates (`realfft`,
//! `rustfft`); no I/O.

use super::influence::pixel_displacement;
use realfft::num_complex::Complex64;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// The smallest even number ≥ `n` whose only prime factors are 2, 3 and 5.
pub fn fast_even_size(n: usize) -> usize {
    let mut m = n.max(2);
    loop {
        if m % 2 == 0 {
            let mut r = m;
            for p in [2, 3, 5] {
                while r % p == 0 {
                    r /= p;
                }
            }
            if r == 1 {
                return m;
            }
        }
        m += 1;
    }
}

/// The half-space operator of one grid: dimensions, pitches, modulus and the kernel's
/// transform, with the FFT plans and work buffers it reuses on every product.
pub struct HalfSpace {
    rows: usize,
    cols: usize,
    /// Padded sizes along x (columns) and y (rows).
    lx: usize,
    ly: usize,
    /// Number of complex frequencies of a real FFT of length `lx`.
    nk: usize,
    /// Kernel transform, divided by lx·ly and by E*, frequency column by column (`nk` × `ly`).
    kernel: Vec<f64>,
    /// Displacement of a pixel's own centre per unit pressure (the kernel at offset 0).
    self_compliance: f64,
    r2c: Arc<dyn RealToComplex<f64>>,
    c2r: Arc<dyn ComplexToReal<f64>>,
    fwd_y: Arc<dyn Fft<f64>>,
    inv_y: Arc<dyn Fft<f64>>,
    row: Vec<f64>,
    row_spec: Vec<Complex64>,
    spec: Vec<Complex64>,
    scratch: Vec<Complex64>,
}

impl std::fmt::Debug for HalfSpace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HalfSpace")
            .field("rows", &self.rows)
            .field("cols", &self.cols)
            .field("padded", &(self.ly, self.lx))
            .finish()
    }
}

impl HalfSpace {
    /// The operator of a `rows × cols` grid with pitches `dx` (along a row) and `dy` (between
    /// rows) on a half-space of composite modulus `modulus`. The caller validates the inputs
    /// (positive finite pitches and modulus, at least one row and column).
    pub fn new(rows: usize, cols: usize, dx: f64, dy: f64, modulus: f64) -> HalfSpace {
        let lx = fast_even_size(2 * cols - 1);
        let ly = fast_even_size(2 * rows - 1);
        let nk = lx / 2 + 1;
        let mut real = RealFftPlanner::<f64>::new();
        let r2c = real.plan_fft_forward(lx);
        let c2r = real.plan_fft_inverse(lx);
        let mut complex = FftPlanner::<f64>::new();
        let fwd_y = complex.plan_fft_forward(ly);
        let inv_y = complex.plan_fft_inverse(ly);
        let scratch_len = fwd_y
            .get_inplace_scratch_len()
            .max(inv_y.get_inplace_scratch_len())
            .max(r2c.get_scratch_len())
            .max(c2r.get_scratch_len());
        let mut space = HalfSpace {
            rows,
            cols,
            lx,
            ly,
            nk,
            kernel: vec![0.0; nk * ly],
            self_compliance: pixel_displacement(0.0, 0.0, dx, dy) / modulus,
            r2c,
            c2r,
            fwd_y,
            inv_y,
            row: vec![0.0; lx],
            row_spec: vec![Complex64::default(); nk],
            spec: vec![Complex64::default(); nk * ly],
            scratch: vec![Complex64::default(); scratch_len],
        };
        space.transform_kernel(dx, dy, modulus);
        space
    }

    /// Fills `kernel` with the transform of the influence coefficients at the padded grid's
    /// offsets: index i ↦ offset i for i < n, i − L for i > L − n, zero between.
    fn transform_kernel(&mut self, dx: f64, dy: f64, modulus: f64) {
        let (rows, cols, lx, ly, nk) = (self.rows, self.cols, self.lx, self.ly, self.nk);
        let offset = |i: usize, n: usize, l: usize| -> Option<f64> {
            if i < n {
                Some(i as f64)
            } else if i > l - n {
                Some(i as f64 - l as f64)
            } else {
                None
            }
        };
        self.spec.fill(Complex64::default());
        // Rows j and ly − j of the kernel are equal (even in y): transform each once.
        for j in 0..rows {
            let y = j as f64 * dy;
            for i in 0..lx {
                self.row[i] = offset(i, cols, lx)
                    .map(|k| pixel_displacement(k * dx, y, dx, dy))
                    .unwrap_or(0.0);
            }
            self.r2c
                .process_with_scratch(&mut self.row, &mut self.row_spec, &mut self.scratch)
                .expect("buffer sizes come from the plan");
            for k in 0..nk {
                self.spec[k * ly + j] = self.row_spec[k];
                if j > 0 {
                    self.spec[k * ly + ly - j] = self.row_spec[k];
                }
            }
        }
        self.fwd_y
            .process_with_scratch(&mut self.spec, &mut self.scratch);
        let norm = 1.0 / (lx as f64 * ly as f64 * modulus);
        for (g, s) in self.kernel.iter_mut().zip(&self.spec) {
            // The kernel is even in both axes: its transform is real up to rounding.
            *g = s.re * norm;
        }
    }

    /// Grid rows (lines along y).
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Grid columns (points along x).
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// The padded grid the convolution runs on, (rows, columns).
    pub fn padded(&self) -> (usize, usize) {
        (self.ly, self.lx)
    }

    /// Displacement of a pixel's centre per unit pressure on that pixel alone.
    pub fn self_compliance(&self) -> f64 {
        self.self_compliance
    }

    /// Bytes of working memory this operator holds (kernel transform, spectra, buffers).
    pub fn memory_bytes(&self) -> usize {
        self.kernel.len() * 8
            + (self.spec.len() + self.row_spec.len() + self.scratch.len()) * 16
            + self.row.len() * 8
    }

    /// `out = K p`: the displacements of every grid point under the pixel pressures `p`
    /// (both row-major, `rows × cols`).
    pub fn displacements(&mut self, p: &[f64], out: &mut [f64]) {
        let (rows, cols, ly, nk) = (self.rows, self.cols, self.ly, self.nk);
        assert_eq!(p.len(), rows * cols, "pressures must cover the grid");
        assert_eq!(out.len(), rows * cols, "displacements must cover the grid");
        for r in 0..rows {
            self.row[..cols].copy_from_slice(&p[r * cols..(r + 1) * cols]);
            self.row[cols..].fill(0.0);
            self.r2c
                .process_with_scratch(&mut self.row, &mut self.row_spec, &mut self.scratch)
                .expect("buffer sizes come from the plan");
            for (k, v) in self.row_spec.iter().enumerate() {
                self.spec[k * ly + r] = *v;
            }
        }
        for k in 0..nk {
            self.spec[k * ly + rows..(k + 1) * ly].fill(Complex64::default());
        }
        self.fwd_y
            .process_with_scratch(&mut self.spec, &mut self.scratch);
        for (s, g) in self.spec.iter_mut().zip(&self.kernel) {
            *s *= *g;
        }
        self.inv_y
            .process_with_scratch(&mut self.spec, &mut self.scratch);
        for r in 0..rows {
            for k in 0..nk {
                self.row_spec[k] = self.spec[k * ly + r];
            }
            // A real signal's transform has real DC and Nyquist terms; rounding leaves a trace
            // of imaginary part that the inverse real FFT refuses.
            self.row_spec[0].im = 0.0;
            self.row_spec[nk - 1].im = 0.0;
            self.c2r
                .process_with_scratch(&mut self.row_spec, &mut self.row, &mut self.scratch)
                .expect("buffer sizes come from the plan");
            out[r * cols..(r + 1) * cols].copy_from_slice(&self.row[..cols]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_sizes_are_even_5_smooth() {
        assert_eq!(fast_even_size(61), 64);
        assert_eq!(fast_even_size(15999), 16000);
        assert_eq!(fast_even_size(1), 2);
        assert_eq!(fast_even_size(7), 8);
        assert_eq!(fast_even_size(11), 12);
        assert_eq!(fast_even_size(1125), 1152);
    }

    /// The FFT product equals the direct sum Σ K(x_i − x_j) p_j on a small anisotropic grid.
    #[test]
    fn fft_product_equals_direct_summation() {
        let (rows, cols, dx, dy, e) = (5, 9, 0.5, 3.0, 2.0);
        let p: Vec<f64> = (0..rows * cols)
            .map(|i| ((i * 37 % 11) as f64 - 3.0).max(0.0) + 0.1 * i as f64)
            .collect();
        let mut space = HalfSpace::new(rows, cols, dx, dy, e);
        let mut got = vec![0.0; rows * cols];
        space.displacements(&p, &mut got);
        for r in 0..rows {
            for c in 0..cols {
                let mut want = 0.0;
                for r2 in 0..rows {
                    for c2 in 0..cols {
                        let x = (c as f64 - c2 as f64) * dx;
                        let y = (r as f64 - r2 as f64) * dy;
                        want += pixel_displacement(x, y, dx, dy) / e * p[r2 * cols + c2];
                    }
                }
                let g = got[r * cols + c];
                assert!(
                    (g - want).abs() < 1e-12 * want.abs().max(1.0),
                    "{r},{c}: {g} vs {want}"
                );
            }
        }
        // A second product reuses the buffers and gives the same answer.
        let mut again = vec![0.0; rows * cols];
        space.displacements(&p, &mut again);
        assert_eq!(got, again);
    }

    /// One row or one column is a grid too: the padding logic holds at n = 1.
    #[test]
    fn single_row_grid() {
        let (rows, cols, dx, dy) = (1, 4, 1.0, 2.0);
        let p = [1.0, 0.0, 0.0, 2.0];
        let mut space = HalfSpace::new(rows, cols, dx, dy, 1.0);
        let mut got = [0.0; 4];
        space.displacements(&p, &mut got);
        for (c, &g) in got.iter().enumerate() {
            let want = pixel_displacement(c as f64 * dx, 0.0, dx, dy)
                + 2.0 * pixel_displacement((c as f64 - 3.0) * dx, 0.0, dx, dy);
            assert!((g - want).abs() < 1e-12);
        }
    }
}
