//! A PDF of an HTML report page, made without a browser: the page's blocks
//! ([`markup`]) typeset on A4 or Letter ([`layout`]) and drawn with krilla — text in the
//! bundled DejaVu Sans, Sans Bold (headings, table headers) and Sans Mono (`<code>`: hashes,
//! identifiers), each embedded and subset (every glyph the report uses: µ, λ, Δ, ≤, ·),
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
//! The document is PDF/A-2b, the archival form a signed record is kept in: krilla's PDF/A-2b
//! validator refuses what the standard forbids (a glyph missing from its font, interpolated
//! images, device colours without the sRGB output intent it writes, a missing date or XMP),
//! and a report it refuses is written as a plain PDF with the reason.
//!
//! Layer 4 (a renderer at the process edge): depends on krilla, krilla-svg, usvg and
//! ab_glyph (the font's advances); bytes in, bytes out.

pub mod layout;
pub mod markup;

use krilla::color::rgb;
use krilla::configure::Validator;
use krilla::error::KrillaError;
use krilla::geom::{PathBuilder, Point, Rect, Size, Transform};
use krilla::metadata::Metadata;
use krilla::num::NormalizedF32;
use krilla::paint::{Fill, Stroke};
use krilla::surface::Surface;
use krilla::text::{Font, GlyphId, KrillaGlyph};
use krilla::Document;
use krilla_svg::{SurfaceExt, SvgSettings};
use layout::{Face, Item, Measure, Rgb, Running, Sheet};
use markup::Block;
use std::sync::Arc;

/// DejaVu Sans (the font the report's figures are drawn with), its bold and its monospaced
/// face (`assets/fonts/`), in the order of [`Face`].
const FONTS: [(&str, &[u8]); 3] = [
    (
        "DejaVuSans.ttf",
        include_bytes!("../../assets/fonts/DejaVuSans.ttf"),
    ),
    (
        "DejaVuSans-Bold.ttf",
        include_bytes!("../../assets/fonts/DejaVuSans-Bold.ttf"),
    ),
    (
        "DejaVuSansMono.ttf",
        include_bytes!("../../assets/fonts/DejaVuSansMono.ttf"),
    ),
];

/// Why no PDF could be made.
#[derive(Debug, thiserror::Error)]
pub enum PdfError {
    /// A font inside the binary cannot be read.
    #[error("the bundled font assets/fonts/{0} cannot be read (the binary is damaged)")]
    Font(&'static str),
    /// krilla refused the document.
    #[error("the PDF could not be assembled: {0}")]
    Assemble(String),
}

/// The bundled faces' advances, in the order of [`Face`].
struct Advances<'a>([ab_glyph::FontRef<'a>; 3]);

impl Advances<'_> {
    fn glyph(&self, c: char, face: Face) -> (u16, f32) {
        use ab_glyph::Font as _;
        let f = &self.0[face as usize];
        let id = f.glyph_id(c);
        let em = f.units_per_em().unwrap_or(2048.0);
        (id.0, f.h_advance_unscaled(id) / em)
    }
}

impl Measure for Advances<'_> {
    fn width(&self, text: &str, size: f32, face: Face) -> f32 {
        text.chars().map(|c| self.glyph(c, face).1).sum::<f32>() * size
    }
}

/// The bundled faces, read for measuring and for krilla.
fn faces() -> Result<(Advances<'static>, [Font; 3]), PdfError> {
    let read = |(name, bytes): (&'static str, &'static [u8])| {
        let face = ab_glyph::FontRef::try_from_slice(bytes).map_err(|_| PdfError::Font(name))?;
        let font = Font::new(bytes.to_vec().into(), 0).ok_or(PdfError::Font(name))?;
        Ok((face, font))
    };
    let [r, b, m] = FONTS.map(read);
    let ((r, rf), (b, bf), (m, mf)) = (r?, b?, m?);
    Ok((Advances([r, b, m]), [rf, bf, mf]))
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
            "image/png" => krilla::image::Image::from_png(data(), false)
                .map(Prepared::Raster)
                .map_err(|e| format!("its PNG cannot be read ({e})")),
            "image/jpeg" => krilla::image::Image::from_jpeg(data(), false)
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

/// A PDF made, and what it lacks.
pub struct Made {
    /// The document.
    pub pdf: Vec<u8>,
    /// What kept it from PDF/A-2b, for the user (it is then a plain PDF of the same pages).
    pub warnings: Vec<String>,
}

/// Why an image (`image/png`, `image/jpeg`, `image/svg+xml`) cannot be drawn into a PDF, or
/// `None` when it can: a laboratory's logo is checked before it heads the report.
pub fn image_error(media_type: &str, bytes: &[u8]) -> Option<String> {
    let image = markup::Image {
        media_type: media_type.to_string(),
        bytes: bytes.to_vec(),
    };
    Prepared::read(&image, &Arc::new(usvg::fontdb::Database::new())).err()
}

/// The page `html` (as a report's HTML renderer writes it) as a PDF/A-2b (ISO 19005-2,
/// level B: an archived record that renders the same in decades) on A4 (or Letter), with
/// `running` along the top and bottom of every page and `title`, `creator` and `created` in
/// the document's information and XMP. What PDF/A-2b forbids (a glyph no bundled face has,
/// a CMYK logo with no profile) makes a plain PDF of the same pages instead, and says why.
pub fn html_to_pdf(
    html: &str,
    letter: bool,
    running: &Running,
    title: &str,
    creator: &str,
    created: chrono::DateTime<chrono::Utc>,
) -> Result<Made, PdfError> {
    let blocks = markup::blocks(html);
    let (advances, font) = faces()?;
    let mut fonts = usvg::fontdb::Database::new();
    for (_, bytes) in FONTS {
        fonts.load_font_data(bytes.to_vec());
    }
    fonts.set_sans_serif_family("DejaVu Sans");
    fonts.set_monospace_family("DejaVu Sans Mono");
    let fonts = Arc::new(fonts);
    let prepared: Vec<Result<Prepared, String>> = blocks
        .iter()
        .filter_map(|b| match b {
            Block::Image { image, .. } => Some(Prepared::read(image, &fonts)),
            _ => None,
        })
        .collect();
    let mut warnings = Vec::new();
    let sizes: Vec<layout::ImageSize> = prepared
        .iter()
        .map(|p| p.as_ref().map(Prepared::size).map_err(Clone::clone))
        .collect();
    let sheet = Sheet::new(letter);
    let laid = layout::typeset(&blocks, &sizes, sheet, running, &advances);
    use chrono::{Datelike, Timelike};
    let date = krilla::metadata::DateTime::new(created.year() as u16)
        .month(created.month() as u8)
        .day(created.day() as u8)
        .hour(created.hour() as u8)
        .minute(created.minute() as u8)
        .second(created.second() as u8)
        .utc_offset_hour(0)
        .utc_offset_minute(0);
    let settings = krilla::page::PageSettings::from_wh(sheet.width, sheet.height)
        .ok_or_else(|| PdfError::Assemble("the sheet has no size".into()))?;
    let write = |validator| {
        let mut doc = Document::new_with(krilla::SerializeSettings {
            configuration: krilla::configure::Configuration::new_with_validator(validator),
            ..Default::default()
        });
        doc.set_metadata(
            Metadata::new()
                .title(title.to_string())
                .creator(creator.to_string())
                .producer(creator.to_string())
                .language("en".to_string())
                .creation_date(date),
        );
        for items in &laid.pages {
            let mut page = doc.start_page_with(settings.clone());
            let mut surface = page.surface();
            for item in items {
                draw(&mut surface, item, &font, &advances, &prepared);
            }
            surface.finish();
            page.finish();
        }
        doc.finish()
    };
    let pdf = match write(Validator::A2_B) {
        Err(KrillaError::Validation(why)) => {
            let why: Vec<String> = why.iter().map(hindrance).collect();
            warnings.push(format!("the PDF is not PDF/A-2b: {}", why.join("; ")));
            write(Validator::None)
        }
        made => made,
    };
    Ok(Made {
        pdf: pdf.map_err(|e| PdfError::Assemble(format!("{e:?}")))?,
        warnings,
    })
}

/// What a PDF/A-2b hindrance is, in words.
fn hindrance(e: &krilla::configure::ValidationError) -> String {
    use krilla::configure::ValidationError as V;
    match e {
        V::ContainsNotDefGlyph(_, _, text) => {
            format!("the bundled fonts have no glyph for {text:?}")
        }
        V::MissingCMYKProfile => "an image is in CMYK without a colour profile".into(),
        other => format!("{other:?}"),
    }
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
    font: &[Font; 3],
    advances: &Advances<'_>,
    images: &[Result<Prepared, String>],
) {
    match item {
        Item::Text {
            x,
            y,
            size,
            face,
            colour,
            text,
        } => {
            let glyphs: Vec<KrillaGlyph> = text
                .char_indices()
                .map(|(i, c)| {
                    let (id, adv) = advances.glyph(c, *face);
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
            surface.set_stroke(None);
            surface.draw_glyphs(
                Point::from_xy(*x, *y),
                &glyphs,
                font[*face as usize].clone(),
                text,
                *size,
                false,
            );
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
