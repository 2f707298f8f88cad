//! A profile CSV gets the report a grid gets: `surfscan analyze` of the real Mitutoyo export
//! writes `report.html` with the assessed profile (its sampling lengths marked λc apart) above
//! its Rk construction, and the SJ series' reading beside ISO's, as the instrument's printout
//! gives it; the sections that need two lines or more say they do not apply, and the run is
//! complete (exit 0).

use crate::common::cdp::Browser;
use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// The SVG attribute `name` of the element `tag` (its text up to `>`).
fn attr<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let at = tag.find(&format!(" {name}=\""))? + name.len() + 3;
    tag[at..].split('"').next()
}

fn num(tag: &str, name: &str) -> f64 {
    attr(tag, name)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no number {name} in {tag}"))
}

/// Every `<tag …>` of `svg` with, for `<text>`, its content.
fn elements<'a>(svg: &'a str, tag: &str) -> Vec<(&'a str, &'a str)> {
    let open = format!("<{tag} ");
    svg.match_indices(&open)
        .map(|(at, _)| {
            let head = &svg[at..at + svg[at..].find('>').unwrap()];
            let body = svg[at + head.len() + 1..]
                .split('<')
                .next()
                .unwrap_or("")
                .trim();
            (head, body)
        })
        .collect()
}

/// The points of a `<polyline>`.
fn points(tag: &str) -> Vec<(f64, f64)> {
    attr(tag, "points")
        .unwrap()
        .split_whitespace()
        .map(|p| {
            let (x, y) = p.split_once(',').unwrap();
            (x.parse().unwrap(), y.parse().unwrap())
        })
        .collect()
}

/// `surfscan analyze INPUT ARGS --out OUT`, run to its end.
fn analyze(input: &Path, args: &[&str], out: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("analyze")
        .arg(input)
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn the_mitutoyo_export_gets_its_profile_figure_and_the_instruments_reading() {
    let csv = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/real/mitutoyo_surftest_R.x_mm_z_um.csv");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    // As the instrument evaluated it (the export's conditions): an R profile, λc 2.5 mm.
    let run = analyze(&csv, &["--no-filter", "--lc", "2.5"], &out);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["kind"], "profile");
    // What one profile cannot have is said, not failed.
    let c = &report["characterisation"];
    assert_eq!(c["complete"], true, "{c}");
    assert_eq!(c["failed_sections"], serde_json::json!([]), "{c}");
    let not_possible: Vec<&str> = c["sections_not_possible"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["section"].as_str().unwrap())
        .collect();
    for s in ["surface_grid", "surface", "between_lines"] {
        assert!(not_possible.contains(&s), "{not_possible:?}");
    }
    assert!(
        stderr.contains("a single profile:") && stderr.contains("do not apply"),
        "{stderr}"
    );
    // The contact of a flat is areal: with --contact it is named as not applying, no failure.
    let args = ["--no-filter", "--lc", "2.5", "--contact"];
    let contact = analyze(&csv, &args, &dir.path().join("contact"));
    let said = String::from_utf8_lossy(&contact.stderr);
    assert_eq!(contact.status.code(), Some(0), "{said}");
    assert!(
        said.contains("between_lines, contact do not apply"),
        "{said}"
    );
    // No height map or pooled bearing curve of a grid that is one line.
    for f in ["heightmap.svg", "bac.svg", "surface3d.svg"] {
        assert!(!out.join(f).exists(), "{f} written for one profile");
    }

    // The figure: the profile drawn over its 9.996 mm, sampling lengths marked λc apart. The
    // profile is the longest data line; its panel, above the Rk construction, spans the
    // heights it is drawn over.
    let svg = std::fs::read_to_string(out.join("rk/0000.svg")).unwrap();
    let profile = elements(&svg, "polyline")
        .into_iter()
        .map(|(t, _)| t)
        .filter(|t| attr(t, "stroke") == Some("#0072B2"))
        .map(points)
        .max_by_key(|p| p.len())
        .unwrap();
    let (top, low) = profile
        .iter()
        .fold((f64::MAX, f64::MIN), |(t, l), p| (t.min(p.1), l.max(p.1)));
    let in_panel = |y: f64| (top - 40.0..=low + 40.0).contains(&y);
    let grey = elements(&svg, "polyline")
        .into_iter()
        .map(|(t, _)| t)
        .filter(|t| attr(t, "stroke") == Some("#6E6E6E"))
        .map(points)
        .filter(|p| p.len() == 2 && p[0].0 == p[1].0 && p[0].1 != p[1].1)
        .filter(|p| in_panel(p[0].1) && in_panel(p[1].1))
        .collect::<Vec<_>>();
    let mut marks: Vec<f64> = grey.iter().map(|p| p[0].0).collect();
    marks.sort_by(f64::total_cmp);
    marks.dedup();
    // The profile's panel ends where its dashes do; its x tick labels sit just below.
    let bottom = grey
        .iter()
        .flat_map(|p| [p[0].1, p[1].1])
        .fold(0.0, f64::max);
    let ticks: Vec<(f64, f64)> = elements(&svg, "text")
        .into_iter()
        .filter(|(t, _)| {
            attr(t, "text-anchor") == Some("middle")
                && (bottom..bottom + 30.0).contains(&num(t, "y"))
        })
        .filter_map(|(t, body)| Some((body.parse::<f64>().ok()?, num(t, "x"))))
        .collect();
    assert!(ticks.len() >= 4, "x ticks of the profile: {ticks:?}");
    // px = a + b·mm, by least squares over the tick labels.
    let n = ticks.len() as f64;
    let (mx, my) = (
        ticks.iter().map(|t| t.0).sum::<f64>() / n,
        ticks.iter().map(|t| t.1).sum::<f64>() / n,
    );
    let b = ticks.iter().map(|t| (t.0 - mx) * (t.1 - my)).sum::<f64>()
        / ticks.iter().map(|t| (t.0 - mx).powi(2)).sum::<f64>();
    let a = my - b * mx;
    let mm = |px: f64| (px - a) / b;
    // N = 4 sampling lengths of λc = 2.5 mm: marks between them at 2.5, 5 and 7.5 mm, each
    // within a pixel and a half of where λc puts it.
    assert_eq!(marks.len(), 3, "sampling-length marks at {marks:?} px");
    for (k, x) in marks.iter().enumerate() {
        let want = 2.5 * (k + 1) as f64;
        assert!(
            (mm(*x) - want).abs() <= 1.5 / b,
            "mark {} at {:.3} mm, not {want} mm",
            k + 1,
            mm(*x)
        );
    }
    for k in 1..=4 {
        assert!(svg.contains(&format!("\nlr{k}\n")), "no label lr{k}");
    }
    // The profile itself spans the evaluation length, and its highest point is where the
    // export's highest ordinate is.
    let (x0, x1) = (profile[0].0, profile[profile.len() - 1].0);
    assert!(mm(x0).abs() <= 1.5 / b && (mm(x1) - 9.9945).abs() <= 1.5 / b);
    let text = std::fs::read_to_string(&csv).unwrap();
    let (x_top, _) = text
        .lines()
        .skip(1)
        .map(|l| {
            let (x, z) = l.split_once(',').unwrap();
            (x.parse::<f64>().unwrap(), z.parse::<f64>().unwrap())
        })
        .fold((0.0, f64::MIN), |m, p| if p.1 > m.1 { p } else { m });
    let first_x = text.lines().nth(1).unwrap().split(',').next().unwrap();
    let x_top = x_top - first_x.parse::<f64>().unwrap();
    let highest = profile.iter().min_by(|p, q| p.1.total_cmp(&q.1)).unwrap();
    assert!(
        (mm(highest.0) - x_top).abs() <= 1.5 / b,
        "the drawn peak is at {:.3} mm, the export's at {x_top:.3} mm",
        mm(highest.0)
    );

    // The page, as Chromium shows it: the figure loaded, and the SJ series' reading with the
    // instrument's printed Rpk 2.912 µm, Rvk 3.980 µm, Mr1 5.822 %, Mr2 92.617 % (the
    // printout, docs/metrology.md) after ISO's table.
    let mut browser = Browser::launch();
    let page = format!("file://{}", out.join("report.html").display());
    let tab = browser.open(&page);
    browser.wait_for(
        &tab,
        "report.html loaded",
        "document.readyState",
        Duration::from_secs(30),
        |v| v == "complete",
    );
    let figure = browser.eval(
        &tab,
        "[...document.images].filter(i => i.alt.includes('assessed profile')).map(i => i.complete && i.naturalWidth > 0 && i.getBoundingClientRect().width > 0)",
    );
    assert_eq!(figure, serde_json::json!([true]), "the profile figure");
    let tables = browser.eval(
        &tab,
        "['t-lines-material', 't-lines-sj'].map(id => { const t = document.getElementById(id); return t && t.checkVisibility() ? t.innerText : null; })",
    );
    let (iso, sj) = (tables[0].as_str().unwrap(), tables[1].as_str().unwrap());
    let row = |t: &str| -> Vec<String> {
        t.lines()
            .find(|l| l.starts_with("1 (0000)"))
            .unwrap_or_else(|| panic!("no row of line 1 in {t}"))
            .split_whitespace()
            .map(str::to_owned)
            .collect()
    };
    let sj_row = row(sj);
    for printed in ["2.912", "3.980", "5.822", "92.617", "0.030"] {
        assert!(
            sj_row.iter().any(|c| c == printed),
            "{printed} not in the SJ reading {sj_row:?}"
        );
    }
    // ISO's reading stays ISO's (Rpk 2.722 µm on the continuous profile).
    assert!(row(iso).iter().any(|c| c == "2.722"), "{iso}");
    // The recipe describes how the profile was evaluated, not a model between lines it has
    // none of.
    let recipe = browser.eval(&tab, "document.getElementById('t-recipe').innerText");
    let recipe = recipe.as_str().unwrap();
    assert!(recipe.contains("sampling lengths N"), "{recipe}");
    assert!(
        !recipe.contains("B-spline") && !recipe.contains("model between lines"),
        "{recipe}"
    );
}

#[test]
fn a_profile_analysed_where_a_grid_was_shows_none_of_the_grids_figures_or_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let grid = dir.path().join("grid.csv");
    let rows: Vec<String> = (0..6)
        .map(|r| {
            (0..400)
                .map(|c| format!("{:.4}", (c as f64 * 0.09 + r as f64 * 0.7).sin()))
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect();
    std::fs::write(&grid, rows.join("\n") + "\n").unwrap();
    let stderr_of = |input: &Path, args: &[&str]| {
        String::from_utf8_lossy(&analyze(input, args, &out).stderr).into_owned()
    };
    let said = stderr_of(
        &grid,
        &["--pitch-x", "0.004", "--pitch-y", "0.01", "--contact"],
    );
    let grid_files = [
        "heightmap.svg",
        "surface3d.svg",
        "psd.svg",
        "acf.svg",
        "model.x3p",
        "contact.json",
        "load_area.svg",
    ];
    for f in grid_files {
        assert!(out.join(f).exists(), "the grid wrote no {f}: {said}");
    }
    // Six lines have means with a spread and an uncertainty.
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(page.contains("<table id=\"t-uncertainty\">"));
    let csv = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/real/mitutoyo_surftest_R.x_mm_z_um.csv");
    let said = stderr_of(&csv, &["--no-filter", "--lc", "2.5"]);
    for f in grid_files.into_iter().chain(["bac.svg", "heightmap.png"]) {
        assert!(
            !out.join(f).exists(),
            "{f} of the grid left beside the profile: {said}"
        );
    }
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    // One line has no mean, s or U over lines: the section says so instead of a table of
    // blanks, on the page and on paper (the PDF typesets the same page).
    let one_line = "One line: its values are those of the per-line tables";
    assert!(!page.contains("t-uncertainty") && page.contains(one_line));
    let pdf = Command::new(env!("CARGO_BIN_EXE_surfscan"))
        .arg("report")
        .arg(&out)
        .arg("--pdf")
        .output()
        .unwrap();
    assert_eq!(pdf.status.code(), Some(0), "{pdf:?}");
    let text = crate::report_print::pdftotext(&out.join("report.pdf"));
    let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        text.contains(one_line) && !text.contains("u of the mean"),
        "{text}"
    );
    for title in [
        "Measured heights",
        "3D view of the measured surface",
        "Autocorrelation",
    ] {
        let caption = format!("<figcaption>{title}</figcaption>");
        assert!(
            !page.contains(&caption),
            "the profile's page shows the grid's {title}"
        );
    }
}
