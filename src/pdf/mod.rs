//! A PDF of an HTML report page, made without a browser: the page's blocks
//! ([`markup`]) typeset on A4 or Letter ([`layout`]) and drawn with krilla — text in the
//! bundled DejaVu Sans, embedded and subset (every glyph the report uses: µ, λ, Δ, ≤, ·),
//! SVG figures as vector drawings through krilla-svg, PNG and JPEG images as images.
//!
//! Why krilla: it is the PDF writer of the Typst project, kept up with it, and writes what a
//! report needs without a browser engine — TrueType fonts embedded and subset with the
//! text extractable (a copy of the numbers stays searchable), vector paths, images, and
//! SVG through its companion crate krilla-svg (built on usvg, which reads what plotters
//! writes). `printpdf` has no SVG import beyond its own subset, and `pdf-writer` + `svg2pdf`
//! leaves fonts, subsetting and the content streams to us; the standard 14 fonts of a
//! hand-written writer cannot encode µ, λ or Δ. The layout is ours: no maintained
//! Rust crate typesets HTML tables across pages, and the report's subset is small.
//!
//! What the browser's print of the page shows, this shows: the same page is read
//! ([`markup`]), so the two never hold different things.
//!
//! Layer 4 (a renderer at the process edge): depends on krilla, krilla-svg, usvg and
//! ab_glyph (the font's advances); bytes in, bytes out.

pub mod layout;
pub mod markup;

use krilla::color::rgb;
use krilla::geom::{PathBuilder, Point, Rect, Size, Transform};
use krilla::metadata::Metadata;
use krilla::num::NormalizedF32;
use krilla::paint::{Fill, Stroke};
use krilla::surface::Surface;
use krilla::text::{Font, GlyphId, KrillaGlyph};
use krilla::Document;
use krilla_svg::{SurfaceExt, SvgSettings};
use layout::{Item, Measure, Rgb, Running, Sheet};
use markup::Block;
use std::sync::Arc;

/// DejaVu Sans, the font the report's figures are drawn with (`assets/fonts/`).
const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Why no PDF could be made.
#[derive(Debug, thiserror::Error)]
pub enum PdfError {
    /// The font inside the binary cannot be read.
    #[error("the bundled font cannot be read (assets/fonts/DejaVuSans.ttf is damaged)")]
    Font,
    /// krilla refused the document.
    #[error("the PDF could not be assembled: {0}")]
    Assemble(String),
}

/// The bundled font's advances.
struct Advances<'a>(ab_glyph::FontRef<'a>);

impl Advances<'_> {
    fn glyph(&self, c: char) -> (u16, f32) {
        use ab_glyph::Font as _;
        let id = self.0.glyph_id(c);
        let em = self.0.units_per_em().unwrap_or(2048.0);
        (id.0, self.0.h_advance_unscaled(id) / em)
    }
}

impl Measure for Advances<'_> {
    fn width(&self, text: &str, size: f32) -> f32 {
        text.chars().map(|c| self.glyph(c).1).sum::<f32>() * size
    }
}

/// One image prepared for drawing.
enum Prepared {
    Svg(Box<usvg::Tree>),
    Raster(krilla::image::Image),
}

impl Prepared {
    fn read(image: &markup::Image, fonts: &Arc<usvg::fontdb::Database>) -> Result<Self, String> {
        let data = || krilla::Data::from(image.bytes.clone());
        match image.media_type.as_str() {
            "image/svg+xml" => {
                let opts = usvg::Options {
                    fontdb: fonts.clone(),
                    ..usvg::Options::default()
                };
                usvg::Tree::from_data(&image.bytes, &opts)
                    .map(|t| Prepared::Svg(Box::new(t)))
                    .map_err(|e| format!("its SVG cannot be read ({e})"))
            }
            "image/png" => krilla::image::Image::from_png(data(), true)
                .map(Prepared::Raster)
                .map_err(|e| format!("its PNG cannot be read ({e})")),
            "image/jpeg" => krilla::image::Image::from_jpeg(data(), true)
                .map(Prepared::Raster)
                .map_err(|e| format!("its JPEG cannot be read ({e})")),
            other => Err(format!("{other} is not an image a PDF can hold")),
        }
    }

    fn size(&self) -> (f32, f32) {
        match self {
            Prepared::Svg(t) => (t.size().width(), t.size().height()),
            Prepared::Raster(i) => {
                let (w, h) = i.size();
                (w as f32, h as f32)
            }
        }
    }
}

/// The page `html` (as a report's HTML renderer writes it) as a PDF on A4 (or Letter), with
/// `running` along the top and bottom of every page and `title` and `creator` in the
/// document's information.
pub fn html_to_pdf(
    html: &str,
    letter: bool,
    running: &Running,
    title: &str,
    creator: &str,
) -> Result<Vec<u8>, PdfError> {
    let blocks = markup::blocks(html);
    let face = ab_glyph::FontRef::try_from_slice(FONT).map_err(|_| PdfError::Font)?;
    let advances = Advances(face);
    let font = Font::new(FONT.to_vec().into(), 0).ok_or(PdfError::Font)?;
    let mut fonts = usvg::fontdb::Database::new();
    fonts.load_font_data(FONT.to_vec());
    fonts.set_sans_serif_family("DejaVu Sans");
    let fonts = Arc::new(fonts);
    let prepared: Vec<Result<Prepared, String>> = blocks
        .iter()
        .filter_map(|b| match b {
            Block::Image { image, .. } => Some(Prepared::read(image, &fonts)),
            _ => None,
        })
        .collect();
    let sizes: Vec<layout::ImageSize> = prepared
        .iter()
        .map(|p| p.as_ref().map(Prepared::size).map_err(Clone::clone))
        .collect();
    let sheet = Sheet::new(letter);
    let laid = layout::typeset(&blocks, &sizes, sheet, running, &advances);
    let mut doc = Document::new();
    doc.set_metadata(
        Metadata::new()
            .title(title.to_string())
            .creator(creator.to_string())
            .producer(creator.to_string()),
    );
    for items in &laid.pages {
        let settings = krilla::page::PageSettings::from_wh(sheet.width, sheet.height)
            .ok_or_else(|| PdfError::Assemble("the sheet has no size".into()))?;
        let mut page = doc.start_page_with(settings);
        let mut surface = page.surface();
        for item in items {
            draw(&mut surface, item, &font, &advances, &prepared);
        }
        surface.finish();
        page.finish();
    }
    doc.finish()
        .map_err(|e| PdfError::Assemble(format!("{e:?}")))
}

fn fill(c: Rgb) -> Fill {
    Fill {
        paint: rgb::Color::new(c.0, c.1, c.2).into(),
        opacity: NormalizedF32::ONE,
        rule: Default::default(),
    }
}

fn draw(
    surface: &mut Surface<'_>,
    item: &Item,
    font: &Font,
    advances: &Advances<'_>,
    images: &[Result<Prepared, String>],
) {
    match item {
        Item::Text {
            x,
            y,
            size,
            bold,
            colour,
            text,
        } => {
            let glyphs: Vec<KrillaGlyph> = text
                .char_indices()
                .map(|(i, c)| {
                    let (id, adv) = advances.glyph(c);
                    KrillaGlyph::new(
                        GlyphId::new(id.into()),
                        adv,
                        0.0,
                        0.0,
                        0.0,
                        i..i + c.len_utf8(),
                        None,
                    )
                })
                .collect();
            surface.set_fill(Some(fill(*colour)));
            // Bold is the regular face drawn with an outline of its own colour.
            surface.set_stroke(bold.then(|| Stroke {
                paint: rgb::Color::new(colour.0, colour.1, colour.2).into(),
                width: size * 0.045,
                ..Stroke::default()
            }));
            surface.draw_glyphs(
                Point::from_xy(*x, *y),
                &glyphs,
                font.clone(),
                text,
                *size,
                false,
            );
            surface.set_stroke(None);
        }
        Item::Fill { x, y, w, h, colour } => {
            if let Some(path) = Rect::from_xywh(*x, *y, *w, *h).and_then(|r| {
                let mut pb = PathBuilder::new();
                pb.push_rect(r);
                pb.finish()
            }) {
                surface.set_stroke(None);
                surface.set_fill(Some(fill(*colour)));
                surface.draw_path(&path);
            }
        }
        Item::Line {
            x1,
            y1,
            x2,
            y2,
            width,
            colour,
        } => {
            let mut pb = PathBuilder::new();
            pb.move_to(*x1, *y1);
            pb.line_to(*x2, *y2);
            if let Some(path) = pb.finish() {
                surface.set_fill(None);
                surface.set_stroke(Some(Stroke {
                    paint: rgb::Color::new(colour.0, colour.1, colour.2).into(),
                    width: *width,
                    ..Stroke::default()
                }));
                surface.draw_path(&path);
                surface.set_stroke(None);
            }
        }
        Item::Image { index, x, y, w, h } => {
            let Some(Ok(image)) = images.get(*index) else {
                return;
            };
            let Some(size) = Size::from_wh(*w, *h) else {
                return;
            };
            surface.push_transform(&Transform::from_translate(*x, *y));
            match image {
                Prepared::Svg(tree) => {
                    surface.draw_svg(tree, size, SvgSettings::default());
                }
                Prepared::Raster(img) => surface.draw_image(img.clone(), size),
            }
            surface.pop();
        }
    }
}
