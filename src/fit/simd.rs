//! Runs the fit's hot loops compiled for AVX2 when the CPU has it, through one dispatch.
//!
//! Only the vector width changes: AVX2 does not include FMA, and Rust never contracts a
//! multiply and an add into one rounding, so every lane performs exactly the IEEE operations
//! of the scalar code and the results are bit-identical on every x86-64 CPU (and elsewhere).
//!
//! Layer 1 (pure logic): depends on `std` only.

/// Calls `f`, compiled with AVX2 enabled when the running CPU supports it. The work `f`
/// does must be `#[inline(always)]` code so it is compiled inside the AVX2 trampoline; the
/// body of a closure is a function of its own, which the compiler need not inline there (the
/// residual check's closure was not: it ran as baseline code, which is why that loop is now
/// written with the AVX2 intrinsics instead).
#[inline(always)]
pub(crate) fn wide<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            return unsafe { avx2(f) };
        }
    }
    f()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}
