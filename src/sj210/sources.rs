//! The documents every table entry of the SJ-210 driver cites, so a reader can check each
//! command string and code where it was read.
//!
//! M1 = SJ-210 manual 99MBB122A (page 17-xx), M2 = SJ-410 manual 99MBB765A, C2 = the public
//! SJ-220 program (ali2644/bachelor-3d-loop), C3 = the public SJ-410 program
//! (KuoKuanLiang/SM9SurfJudgeC). "inferred" marks what no source states.
//!
//! Pure (layer 0 of the driver): constants only, depends on nothing.

/// SJ-210 control commands.
pub const M1_CTL: &str = "M1 p.17-13 (SJ-210 control commands)";
/// SJ-210 status and identity reads.
pub const M1_STU: &str = "M1 p.17-16/17 (SJ-210 STU, SJ_)";
/// SJ-210 conditions and parameter count.
pub const M1_CON: &str = "M1 p.17-18 (SJ-210 CON, PAR)";
/// SJ-210 results.
pub const M1_RES: &str = "M1 p.17-19 (SJ-210 RES)";
/// Listed in the SJ-210 command table; the detail page was not stored.
pub const M1_LIST: &str = "M1 p.17-13 command list (detail page not stored)";
/// SJ-410 control commands.
pub const M2_CTL: &str = "M2 p.22 (SJ-410 STP, OFF, ESP)";
/// SJ-410 profile read-out.
pub const M2_EVA: &str = "M2 p.22 (SJ-410 PSA, EVA)";
/// SJ-410 conditions layout.
pub const M2_CON: &str = "M2 p.22 (SJ-410 CON write layout)";
/// The SJ-220 device error table as the public program carries it.
pub const C2: &str = "C2 sj220_exceptions.py (SJ-220 device table)";
/// The public SJ-410 program.
pub const C3: &str = "C3 Main.cs (SJ-410 program)";
/// What no document says and no instrument was seen doing yet.
pub const UNSEEN: &str =
    "not documented, not yet seen on an instrument (surfscan probe --trace --readout finds out)";
