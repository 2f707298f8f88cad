//! Rasterised text remembered between figures: a drawing backend that wraps a bitmap backend
//! and draws each text from the pixels the font gave the last time the same text was drawn in
//! the same font, size and colour.
//!
//! A report draws the same subtitle, footer, axis titles and tick labels into every one of its
//! Rk figures, and plotters rasterises every glyph outline again each time. plotters' default
//! `draw_text` asks the font for the text's pixels at the origin, then places each one (anchor,
//! rotation, clipping) and blends it with `draw_pixel`. The font's pixels do not depend on
//! where the text goes, so this backend keeps them and replays the same `draw_pixel` calls in
//! the same order: the image is the same to the bit. Neither plotters nor another crate offers
//! such a cache, hence this one.
//!
//! The memo is per thread (each figure thread has its own) and bounded: it is emptied when it
//! would hold more than [`MAX_PIXELS`] pixels. A report's texts are mostly its own (the scan
//! id, the values), so a thread that draws one report after another, as the daemon's does,
//! [`forget`]s them once a report is written rather than holding them up to the bound.
//!
//! Layer 1 (drawing support): depends on `plotters-backend` only.

use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingBackend, DrawingErrorKind,
};
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

/// At most this many remembered pixels per thread (16 bytes each: 16 MiB).
pub const MAX_PIXELS: usize = 1 << 20;

/// What a text's pixels depend on: the text, the font (family, style, size) and the colour.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Key {
    text: String,
    family: String,
    style: String,
    size_bits: u64,
    alpha_bits: u64,
    rgb: (u8, u8, u8),
}

/// The font's pixels of one text drawn at the origin, in the order the font gave them.
type Pixels = Rc<[(i32, i32, BackendColor)]>;

#[derive(Default)]
struct Memo {
    texts: HashMap<Key, Pixels>,
    pixels: usize,
}

thread_local! {
    static MEMO: RefCell<Memo> = RefCell::new(Memo::default());
}

/// Empties this thread's memo and gives its memory back.
pub fn forget() {
    MEMO.with(|m| *m.borrow_mut() = Memo::default());
}

/// How many texts, and how many of their pixels, this thread remembers.
pub fn remembered() -> (usize, usize) {
    MEMO.with(|m| {
        let m = m.borrow();
        (m.texts.len(), m.pixels)
    })
}

/// A bitmap backend (or any backend that draws text pixel by pixel) whose texts are
/// rasterised once per thread; everything else goes straight to the inner backend.
pub struct TextCache<B> {
    inner: B,
}

impl<B> TextCache<B> {
    /// Wraps `inner`.
    pub fn new(inner: B) -> TextCache<B> {
        TextCache { inner }
    }
}

/// The font's pixels of `text` in `style` at the origin, from the memo or from the font.
fn pixels<S: BackendTextStyle>(text: &str, style: &S) -> Result<Pixels, S::FontError> {
    let color = style.color();
    let key = Key {
        text: text.to_string(),
        family: style.family().as_str().to_string(),
        style: style.style().as_str().to_string(),
        size_bits: style.size().to_bits(),
        alpha_bits: color.alpha.to_bits(),
        rgb: color.rgb,
    };
    if let Some(p) = MEMO.with(|m| m.borrow().texts.get(&key).cloned()) {
        return Ok(p);
    }
    let mut drawn = Vec::new();
    // The recording closure never fails, so the inner result is always Ok.
    let _ = style.draw(text, (0, 0), |x, y, c| {
        drawn.push((x, y, c));
        Ok::<(), ()>(())
    })?;
    let p: Pixels = drawn.into();
    MEMO.with(|m| {
        let mut m = m.borrow_mut();
        if m.pixels + p.len() > MAX_PIXELS {
            m.texts.clear();
            m.pixels = 0;
        }
        if p.len() <= MAX_PIXELS {
            m.pixels += p.len();
            m.texts.insert(key, p.clone());
        }
    });
    Ok(p)
}

impl<B: DrawingBackend> DrawingBackend for TextCache<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.fill_polygon(vert, style)
    }

    /// plotters' default `draw_text` step for step (the same early return, the same errors,
    /// the same anchor and clipping arithmetic, the same `draw_pixel` calls in the same
    /// order), with the font's pixels taken from the memo.
    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        if style.color().alpha == 0.0 {
            return Ok(());
        }
        let ((min_x, min_y), (max_x, max_y)) = style
            .layout_box(text)
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let (width, height) = (max_x - min_x, max_y - min_y);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let trans = style.transform();
        let (w, h) = self.get_size();
        let pixels = pixels(text, style).map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        for &(x, y, color) in pixels.iter() {
            let (x, y) = trans.transform(x + dx - min_x, y + dy - min_y);
            let (x, y) = (pos.0 + x, pos.1 + y);
            if x >= 0 && x < w as i32 && y >= 0 && y < h as i32 {
                self.inner.draw_pixel((x, y), color)?;
            }
        }
        Ok(())
    }

    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> Result<(u32, u32), DrawingErrorKind<B::ErrorType>> {
        self.inner.estimate_text_size(text, style)
    }

    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.blit_bitmap(pos, size, src)
    }
}
