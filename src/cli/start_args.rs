//! The options `surfscan scan` and `surfscan start` share for which scan to run: resume the
//! unfinished one or start anew, and a recipe with the y of its first line. Both commands take
//! them with the same words and check them, and `surfscan queue add`'s `--y-start-mm` and
//! operator, the same way.
//!
//! Layer 5 (composition): depends on [`crate::scan::command`].

use super::{CliError, Exit};
use crate::scan::command::StartMode;

/// Which scan to run, as given on the command line.
#[derive(Debug, Clone, clap::Args)]
pub struct StartChoiceArgs {
    /// Continue the newest unfinished or failed scan at its first missing line (after the
    /// cause of a failure was cleared).
    #[arg(long, conflicts_with = "new")]
    pub resume: bool,
    /// Start a new scan even when one is unfinished (that one is recorded as abandoned).
    #[arg(long)]
    pub new: bool,
    /// Scan with this recipe (`NAME.toml` in the station's `[jobs] recipes` directory): its
    /// plan, measuring conditions, analysis and specification, instead of the station's plan.
    #[arg(long, value_name = "NAME")]
    pub recipe: Option<String>,
    /// y of the first line, mm (machine coordinates), for the recipe's scan [default: the
    /// recipe's, else the station's].
    #[arg(
        long,
        value_name = "Y",
        requires = "recipe",
        allow_negative_numbers = true
    )]
    pub y_start_mm: Option<f64>,
}

impl StartChoiceArgs {
    /// Resume, new, or whichever the output directory calls for.
    pub fn mode(&self) -> StartMode {
        StartMode::from_flags(self.resume, self.new)
    }

    /// `--y-start-mm` when it is a position (exit 2 naming the value when it is not).
    pub fn y_start_mm(&self) -> Result<Option<f64>, CliError> {
        y_start_mm(self.y_start_mm)
    }
}

/// A `--y-start-mm` when it is a position (exit 2 naming the value when it is not).
pub fn y_start_mm(y: Option<f64>) -> Result<Option<f64>, CliError> {
    match y {
        Some(y) if !y.is_finite() => Err(CliError::new(
            Exit::Usage,
            format!("--y-start-mm {y} is not a position; give the y of the first line in mm"),
        )),
        y => Ok(y),
    }
}

/// The operator recorded with a scan: `--operator`, else the user running the command.
pub fn operator_or_user(operator: Option<String>) -> String {
    operator
        .or_else(|| std::env::var("USER").ok())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// A command that takes the options as `scan` and `start` do.
    #[derive(Debug, Parser)]
    struct Cmd {
        #[command(flatten)]
        choice: StartChoiceArgs,
    }

    fn parse(args: &[&str]) -> Result<StartChoiceArgs, clap::Error> {
        Cmd::try_parse_from(std::iter::once("cmd").chain(args.iter().copied())).map(|c| c.choice)
    }

    #[test]
    fn resume_and_new_exclude_each_other_and_say_the_mode() {
        assert!(parse(&["--resume", "--new"]).is_err());
        assert_eq!(parse(&["--resume"]).unwrap().mode(), StartMode::Resume);
        assert_eq!(parse(&["--new"]).unwrap().mode(), StartMode::New);
        assert_eq!(parse(&[]).unwrap().mode(), StartMode::Auto);
    }

    #[test]
    fn a_first_line_y_needs_a_recipe_and_may_be_negative() {
        assert!(parse(&["--y-start-mm", "2"]).is_err());
        let c = parse(&["--recipe", "r", "--y-start-mm", "-2.5"]).unwrap();
        assert_eq!(c.recipe.as_deref(), Some("r"));
        assert_eq!(c.y_start_mm().unwrap(), Some(-2.5));
    }

    #[test]
    fn a_first_line_y_that_is_no_position_is_a_usage_error_naming_it() {
        for (given, shown) in [(f64::NAN, "NaN"), (f64::INFINITY, "inf")] {
            let e = y_start_mm(Some(given)).unwrap_err();
            assert!(matches!(e.exit, Exit::Usage), "{e:?}");
            assert!(
                e.message.contains(&format!("--y-start-mm {shown} ")),
                "{e:?}"
            );
        }
        assert_eq!(y_start_mm(None).unwrap(), None);
        assert_eq!(y_start_mm(Some(0.0)).unwrap(), Some(0.0));
    }

    #[test]
    fn the_operator_given_wins_over_the_user() {
        assert_eq!(operator_or_user(Some("ann".into())), "ann");
    }
}
