//! The `surfscan-sim` binary: a thin command line over the `surfscan_sim` library.

fn main() {
    eprintln!("surfscan-sim: no device selected");
    std::process::exit(2);
}
