//! Recipe files: read, checked with the station's ranges, refused naming file and key.

use super::*;

/// The smallest station configuration, as the configuration's own tests use it.
use crate::config::tests::MINIMAL as STATION;

const RECIPE: &str = r#"
description = "brass coupon"
[plan]
lines = 21
y-start-mm = 10.0
y-step-mm = 0.02
[conditions]
lambda-c-mm = 0.8
sampling-lengths = 5
[analysis]
outliers = "exclude"
[specification]
limits = ["Ra 0.8", "Rz max 6.3", "L Ra 0.2"]
"#;

fn station() -> Config {
    Config::parse(Path::new("station.toml"), STATION).unwrap()
}

fn recipe(text: &str) -> Result<Recipe, RecipeError> {
    Recipe::from_text("brass", Path::new("/r/brass.toml"), text, &station())
}

fn refused(text: &str) -> (String, String) {
    match recipe(text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e @ RecipeError::Invalid { .. }) => {
            let RecipeError::Invalid { ref key, .. } = e else {
                unreachable!()
            };
            (key.clone(), e.to_string())
        }
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn a_recipe_replaces_the_plan_and_the_analysis_keys_it_names() {
    let r = recipe(RECIPE).unwrap();
    assert_eq!(r.specification.limits.len(), 3);
    assert_eq!(r.sha256, crate::scan::store::hex_sha256(RECIPE.as_bytes()));
    let c = r.config_for(&station(), None).unwrap();
    assert_eq!(
        (c.scan.lines, c.scan.y_start_mm, c.scan.y_step_mm),
        (21, 10.0, 0.02)
    );
    assert_eq!(c.analysis.outliers, crate::config::OutlierPolicy::Exclude);
    // The keys the recipe does not name stay the station's.
    assert_eq!(c.analysis.curves, station().analysis.curves);
    assert_eq!(c.scan.max_line_attempts, station().scan.max_line_attempts);
    // A job's y start wins over the recipe's; without either, the station's.
    assert_eq!(
        r.config_for(&station(), Some(20.0))
            .unwrap()
            .scan
            .y_start_mm,
        20.0
    );
    let r = recipe(&RECIPE.replace("y-start-mm = 10.0\n", "")).unwrap();
    assert_eq!(r.config_for(&station(), None).unwrap().scan.y_start_mm, 1.0);
    assert!(
        r.summary(&station()).contains("the station's"),
        "{}",
        r.summary(&station())
    );
}

#[test]
fn a_recipe_overrides_the_contact_keys_it_names() {
    let text = format!("{RECIPE}[contact]\nenabled = true\nyoung-gpa = 100.0\n");
    let c = recipe(&text).unwrap().config_for(&station(), None).unwrap();
    assert!(c.contact.enabled);
    assert_eq!(c.contact.young_gpa, 100.0);
    // The keys it does not name stay the station's.
    let d = station().contact;
    assert_eq!(
        (c.contact.poisson, &c.contact.pressures_mpa),
        (d.poisson, &d.pressures_mpa)
    );
    // Without a [contact] table, the station's.
    let c = recipe(RECIPE)
        .unwrap()
        .config_for(&station(), None)
        .unwrap();
    assert_eq!(c.contact, d);
}

#[test]
fn bad_recipes_are_refused_naming_the_file_and_the_key() {
    for (text, key, says) in [
        (
            RECIPE.replace("lines = 21", "lines = 3"),
            "plan.lines",
            "at least 6",
        ),
        (
            RECIPE.replace("lines = 21", "lines = 0"),
            "plan.lines",
            "valid range",
        ),
        (
            RECIPE.replace("y-start-mm = 10.0", "y-start-mm = 49.9"),
            "plan",
            "outside the stage's soft limits",
        ),
        (
            RECIPE.replace("y-step-mm = 0.02", "y-step-mm = 0.0"),
            "plan.y-step-mm",
            "must not be 0",
        ),
        (
            RECIPE.replace("\"Ra 0.8\"", "\"Ra0.8x\""),
            "specification.limits",
            "limits[0]: \"Ra0.8x\"",
        ),
        (
            RECIPE.replace("\"Ra 0.8\"", "\"Ra 0.8 mm\""),
            "specification.limits",
            "limits are written in µm",
        ),
        (
            RECIPE.replace("\"L Ra 0.2\"", "\"L Ra 0.9\""),
            "specification.limits",
            "not below the upper limit",
        ),
        (
            RECIPE.replace("\"L Ra 0.2\"", "\"Sa 0.2\""),
            "specification.limits",
            "not a parameter a scan computes",
        ),
        (
            RECIPE.replace("\"L Ra 0.2\"", "\"Rz3 4\""),
            "specification.limits",
            "asks 3 sampling lengths but [conditions] sampling-lengths = 5",
        ),
        (
            RECIPE.replace("\"L Ra 0.2\"", "\"0.0025-2.5/Rz 4\""),
            "specification.limits",
            "asks λc = 2.5 mm but [conditions] lambda-c-mm = 0.8",
        ),
        (
            RECIPE.replace("lambda-c-mm = 0.8", "lambda-c-mm = 800.0"),
            "conditions.lambda-c-mm",
            "valid range",
        ),
        (
            RECIPE.replace("outliers = \"exclude\"", "spike-threshold-sigma = 0.1"),
            "analysis.spike-threshold-sigma",
            "valid range",
        ),
        (
            RECIPE.replace("outliers = \"exclude\"", "outlier = \"exclude\""),
            "analysis",
            "unknown field `outlier`",
        ),
        (
            format!("{RECIPE}[contact]\nenabled = true\nyoung-gpa = -1.0\n"),
            "contact.young-gpa",
            "valid range",
        ),
        (
            format!("{RECIPE}[contact]\nhardness-gpa = 0.05\npressures-mpa = [100.0]\n"),
            "contact.pressures-mpa",
            "beyond full contact",
        ),
        (
            format!("{RECIPE}[contact]\nyoung = 100.0\n"),
            "contact",
            "unknown field `young`",
        ),
        (
            RECIPE.replace("[conditions]", "[condition]"),
            "",
            "unknown field `condition`",
        ),
        (
            RECIPE.replace("lambda-c-mm", "lambda-c"),
            "",
            "unknown field `lambda-c`",
        ),
        (
            RECIPE.replace("lines = 21\n", ""),
            "",
            "missing field `lines`",
        ),
    ] {
        let (k, e) = refused(&text);
        assert_eq!(k, key, "{e}");
        assert!(e.contains(says), "{e}");
        assert!(e.starts_with("recipe /r/brass.toml: "), "{e}");
    }
}

#[test]
fn a_y_start_from_the_command_line_is_a_usage_error() {
    let r = recipe(RECIPE).unwrap();
    let e = r.config_for(&station(), Some(60.0)).unwrap_err();
    assert!(e.is_usage(), "{e}");
    let text = e.to_string();
    assert!(
        text.starts_with("--y-start-mm: ") && text.contains("soft limits"),
        "{text}"
    );
    let e = r.config_for(&station(), Some(-1.0)).unwrap_err();
    assert!(
        e.is_usage() && e.to_string().contains("line 1 at y = -1"),
        "{e}"
    );
}

#[test]
fn recipes_are_found_by_name_and_unknown_names_list_the_others() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("brass.toml"), RECIPE).unwrap();
    std::fs::write(dir.path().join("steel-7.toml"), RECIPE).unwrap();
    std::fs::write(dir.path().join("notes.txt"), "x").unwrap();
    assert_eq!(names(dir.path()).unwrap(), vec!["brass", "steel-7"]);
    let r = Recipe::load(dir.path(), "steel-7", &station()).unwrap();
    assert_eq!(r.path, dir.path().join("steel-7.toml"));
    let e = Recipe::load(dir.path(), "bras", &station()).unwrap_err();
    assert!(e.is_usage());
    assert!(
        e.to_string()
            .contains("the recipes there are brass, steel-7"),
        "{e}"
    );
    for bad in ["../brass", "", ".hidden", "a/b"] {
        let e = Recipe::load(dir.path(), bad, &station()).unwrap_err();
        assert!(matches!(e, RecipeError::BadName { .. }), "{bad}: {e}");
    }
    assert!(names(&dir.path().join("absent")).unwrap().is_empty());
}
