//! Fit benchmark (filled in with the fitter).
fn main() {}
