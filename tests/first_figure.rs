//! A figure laid out before any other figure of the process. The height map sizes its frame
//! (title, subtitle, wrapped footer) before it draws, so the bundled font must be registered
//! before those texts are measured, not only when drawing starts. This test is a binary of its
//! own so that no other test has drawn a figure, and so registered the font, before it runs.

use surfscan::metrology::areal::HeightMap;
use surfscan::report::render::plots::plot_height_map;

/// The contents of the SVG's `<text>` elements, in document order.
fn texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| {
            let start = t.find('>')? + 1;
            let end = t.find("</text>")?;
            Some(t.get(start..end)?.trim().to_string())
        })
        .collect()
}

#[test]
fn the_first_height_map_of_a_process_wraps_its_footer_to_the_figure() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (31, 400);
    let heights: Vec<f64> = (0..rows * cols)
        .map(|k| (k as f64 * 0.013).sin() + 0.2 * (k as f64 * 0.31).cos())
        .collect();
    let grid = HeightMap {
        heights_um: &heights,
        rows,
        cols,
        pitch_x_mm: 0.0005,
        pitch_y_mm: 0.01,
    };
    // A scan's traceability footer: far wider than the figure on one line.
    let caption = "specimen demo: Mitutoyo R profile windows · sj210 fw V1.00 (000 standard) · ISO1997 Gaussian λc 2.5 mm λs 8 µm arbitrary evaluation length · scan 20261203T072144Z-demo-mitutoyo-r-profile-windows · surfscan 0.1.0 (commit 0123456789ab)";
    let [png, svg] =
        plot_height_map(dir.path(), &grid, (0.0, 0.0), "Measured heights", caption).unwrap();
    assert!(png.exists());
    let texts = texts(&std::fs::read_to_string(&svg).unwrap());
    let first = texts
        .iter()
        .position(|t| t.starts_with("specimen demo"))
        .unwrap_or_else(|| panic!("no footer in {texts:?}"));
    let last = texts
        .iter()
        .position(|t| t.ends_with("(commit 0123456789ab)"))
        .unwrap_or_else(|| panic!("no footer end in {texts:?}"));
    assert!(
        last > first,
        "the footer is one line, measured as if it had no width: {:?}",
        &texts[first..=last.max(first)]
    );
    // Wrapped, not cut: the footer's lines are the caption's words in order.
    assert_eq!(
        texts[first..=last].join(" "),
        caption.split_whitespace().collect::<Vec<_>>().join(" ")
    );
}
