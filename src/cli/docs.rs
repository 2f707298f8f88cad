//! `surfscan completions SHELL` and `surfscan manpages DIR`: shell completions and man pages
//! generated from the command-line definition itself (clap_complete, clap_mangen), so they
//! never drift from the options the binary accepts. Installing them is one documented step
//! (README, "Installing on a station").
//!
//! Exit status: 0 written, 74 the directory or a page cannot be written.
//!
//! Layer 5 (composition): depends on [`super::Cli`].

use super::{Cli, CliError, Exit};
use clap::CommandFactory;
use std::path::{Path, PathBuf};

/// Arguments of `surfscan completions`.
#[derive(Debug, clap::Args)]
pub struct CompletionsArgs {
    /// The shell to complete for.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// Arguments of `surfscan manpages`.
#[derive(Debug, clap::Args)]
pub struct ManpagesArgs {
    /// Directory for the pages (created if missing), e.g. /usr/local/share/man/man1.
    pub dir: PathBuf,
}

/// Runs `surfscan completions SHELL`: the script on standard output.
pub fn run_completions(args: CompletionsArgs) -> Result<(), CliError> {
    let mut cmd = Cli::command();
    // Rendered in memory (a write to a closed stdout would panic inside the generator),
    // then printed as any other output is.
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "surfscan", &mut script);
    super::console::out_bytes(&script);
    Ok(())
}

/// Writes `surfscan.1` and `surfscan-SUBCOMMAND.1` for every subcommand into `dir`;
/// returns the files written.
pub fn write_manpages(dir: &Path) -> Result<Vec<PathBuf>, CliError> {
    let io = |p: &Path, e: std::io::Error| {
        CliError::new(Exit::Io, format!("cannot write {}: {e}", p.display()))
    };
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let cmd = Cli::command();
    let mut written = Vec::new();
    let mut page = |cmd: clap::Command, name: String| -> Result<(), CliError> {
        let path = dir.join(format!("{name}.1"));
        let mut buf = Vec::new();
        clap_mangen::Man::new(cmd.display_name(name))
            .render(&mut buf)
            .map_err(|e| io(&path, e))?;
        crate::atomic::write_atomically(&path, |w| std::io::Write::write_all(w, &buf))
            .map_err(|e| io(&path, e))?;
        written.push(path);
        Ok(())
    };
    for sub in cmd.get_subcommands() {
        let name = format!("surfscan-{}", sub.get_name());
        // The subcommand's page carries the version and the global options too.
        let sub = sub
            .clone()
            .version(crate::build_info::LONG_VERSION)
            // The version goes on the page, but a subcommand takes no -V/--version.
            .disable_version_flag(true)
            .args(cmd.get_arguments().filter(|a| a.is_global_set()).cloned());
        page(sub, name)?;
    }
    page(cmd, "surfscan".to_string())?;
    Ok(written)
}

/// Runs `surfscan manpages DIR`.
pub fn run_manpages(args: ManpagesArgs) -> Result<(), CliError> {
    let written = write_manpages(&args.dir)?;
    say!(
        "wrote {} man pages into {} (surfscan.1 and one per subcommand)",
        written.len(),
        args.dir.display()
    );
    Ok(())
}
