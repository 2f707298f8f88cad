//! Surface characterisation: ISO 4287/21920 roughness per line, ISO 13565-2 Rk family, bearing area curves from the NURBS model, areal parameters, plots, X3P.
//!
//! Layer 1 (pure logic) except the writers of plots and X3P, which take a directory from the caller.
