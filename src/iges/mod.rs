//! IGES 5.3 writer (entity 128, millimetres) and a reader of the entities it writes.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`]; writes to any `io::Write`, never opens files.
