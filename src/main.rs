//! The `surfscan` binary: parse arguments, start logging, run the command, map the result to
//! a sysexits code. The work lives in the library (`surfscan::cli`).

use clap::Parser;
use surfscan::cli::{self, Cli};

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            std::process::exit(if e.use_stderr() {
                cli::Exit::Usage as i32
            } else {
                0
            });
        }
    };
    surfscan::telemetry::init(cli.verbose);
    // A panic that no layer ended earlier (`surfscan::panics`) ends the command with the
    // documented internal-error status, not Rust's 101.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| cli::run(cli))) {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            cli::console::err(format_args!("surfscan: {e}"));
            std::process::exit(e.exit as i32);
        }
        Err(p) => surfscan::panics::exit_internal("the command", surfscan::panics::message(&*p)),
    }
}
