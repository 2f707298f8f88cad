//! The blocks of a page set on paper: paragraphs wrapped to the measure, tables given column
//! widths that fit and split between pages on row boundaries with their heading rows
//! repeated, figures and headings kept whole and with what follows them, the running
//! header and footer with "page N of M".
//!
//! Pure: blocks and the text's widths in, pages of positioned items out (points, origin at
//! the page's top left, y downwards). Depends on [`super::markup`].

use super::markup::{Block, Cell, Kind, Row, Run, Style, Tone};

/// Millimetres in points.
pub const MM: f32 = 72.0 / 25.4;

/// The sheet and its margins, in points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sheet {
    /// The sheet's width.
    pub width: f32,
    /// The sheet's height.
    pub height: f32,
    /// The top margin.
    pub top: f32,
    /// The right margin.
    pub right: f32,
    /// The bottom margin.
    pub bottom: f32,
    /// The left margin.
    pub left: f32,
}

impl Sheet {
    /// A4 or US Letter with the printed report's margins: 16, 13, 17, 13 mm on A4; 10 and 11
    /// mm at top and bottom on Letter, which is 17.6 mm shorter.
    pub fn new(letter: bool) -> Sheet {
        let (width, height, top, bottom) = if letter {
            (612.0, 792.0, 10.0, 11.0)
        } else {
            (210.0 * MM, 297.0 * MM, 16.0, 17.0)
        };
        Sheet {
            width,
            height,
            top: top * MM,
            right: 13.0 * MM,
            bottom: bottom * MM,
            left: 13.0 * MM,
        }
    }

    fn measure(&self) -> f32 {
        self.width - self.left - self.right
    }

    fn foot(&self) -> f32 {
        self.height - self.bottom
    }
}

/// The words along the top and bottom of every page.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Running {
    /// Top left (the laboratory).
    pub top_left: String,
    /// Top right (what the report is of); left out when it would run into the top left.
    pub top_right: String,
    /// Bottom left (the software); "page N of M" is at the bottom right.
    pub bottom_left: String,
}

/// A colour, 0–255 each.
pub type Rgb = (u8, u8, u8);

/// Text.
pub const INK: Rgb = (0x22, 0x22, 0x22);
/// Text of less weight.
pub const MUTED: Rgb = (0x66, 0x66, 0x66);
const FLAG: Rgb = (0xbb, 0, 0);
const BORDER: Rgb = (0xcc, 0xcc, 0xcc);
const HEAD_FILL: Rgb = (0xf2, 0xf2, 0xf2);

/// One thing drawn on a page.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// Text from `x` along the baseline `y`.
    #[allow(missing_docs)]
    Text {
        x: f32,
        y: f32,
        size: f32,
        face: Face,
        colour: Rgb,
        text: String,
    },
    /// A filled rectangle.
    #[allow(missing_docs)]
    Fill {
        x: f32,
        y: f32,
        w: f32,
        h: f32,
        colour: Rgb,
    },
    /// A line.
    #[allow(missing_docs)]
    Line {
        x1: f32,
        y1: f32,
        x2: f32,
        y2: f32,
        width: f32,
        colour: Rgb,
    },
    /// The `index`th image of the blocks, in their order, scaled into the box.
    #[allow(missing_docs)]
    Image {
        index: usize,
        x: f32,
        y: f32,
        w: f32,
        h: f32,
    },
}

/// Which of the bundled faces text is set in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Face {
    /// DejaVu Sans.
    Regular,
    /// DejaVu Sans Bold: headings, captions, table headers, `<b>`.
    Bold,
    /// DejaVu Sans Mono: `<code>` (hashes, identifiers); bold inside it stays mono.
    Mono,
}

impl Face {
    /// The face `style` is set in.
    pub fn of(style: Style) -> Face {
        match (style.mono, style.bold) {
            (true, _) => Face::Mono,
            (false, true) => Face::Bold,
            (false, false) => Face::Regular,
        }
    }
}

/// The width of text.
pub trait Measure {
    /// The advance of `text` at `size` points in `face`.
    fn width(&self, text: &str, size: f32, face: Face) -> f32;
}

/// `style` made bold (a heading's or a table header's runs).
fn emboldened(style: Style, bold: bool) -> Style {
    Style {
        bold: style.bold || bold,
        ..style
    }
}

/// What the typesetter knows of an image: its size, or why it cannot be drawn.
pub type ImageSize = Result<(f32, f32), String>;

const BODY: f32 = 9.0;
const TABLE: f32 = 7.5;
const LEADING: f32 = 1.3;
/// Table rows are set closer than prose.
const TABLE_LEADING: f32 = 1.15;
const PAD_X: f32 = 3.0;
const PAD_Y: f32 = 0.5;
const FIGURE_MAX_H: f32 = 70.0 * MM;
const LOGO_MAX: (f32, f32) = (50.0 * MM, 18.0 * MM);
const TONE_INDENT: f32 = 8.0;

fn size_of(kind: Kind) -> f32 {
    match kind {
        Kind::Heading(1) => 14.0,
        Kind::Heading(2) => 11.0,
        Kind::Heading(_) => 9.5,
        Kind::LabName => 11.0,
        _ => BODY,
    }
}

fn colour(style: Style) -> Rgb {
    if style.flag {
        FLAG
    } else if style.muted {
        MUTED
    } else {
        INK
    }
}

fn tone_colours(tone: Tone) -> Option<(Rgb, Rgb)> {
    match tone {
        Tone::Plain => None,
        Tone::Warn => Some(((0xd5, 0x5e, 0), (0xff, 0xf4, 0xe5))),
        Tone::Ok => Some(((0, 0x9e, 0x73), (0xee, 0xf7, 0xf1))),
        Tone::Bad => Some(((0xb2, 0x18, 0x2b), (0xfd, 0xec, 0xea))),
    }
}

/// A piece of a line: its offset from the line's start, its style, its text.
#[derive(Debug, Clone, PartialEq)]
pub struct Piece {
    /// From the line's start, points.
    pub dx: f32,
    /// How it is set.
    pub style: Style,
    /// What it says.
    pub text: String,
}

fn piece_size(size: f32, style: Style) -> f32 {
    if style.sub {
        size * 0.75
    } else {
        size
    }
}

/// The runs broken into lines no wider than `width` at `size`: at spaces, and inside a word
/// only when the word alone is wider than the line.
pub fn wrap(runs: &[Run], size: f32, width: f32, m: &dyn Measure) -> Vec<Vec<Piece>> {
    // Words: pieces of runs between spaces; a '\n' ends a line.
    enum Tok {
        Word(Vec<(Style, String)>),
        Space(Style),
        Break,
    }
    let mut toks: Vec<Tok> = Vec::new();
    for r in runs {
        let mut word = String::new();
        let push_word = |toks: &mut Vec<Tok>, word: &mut String| {
            if word.is_empty() {
                return;
            }
            let w = std::mem::take(word);
            match toks.last_mut() {
                Some(Tok::Word(parts)) => parts.push((r.style, w)),
                _ => toks.push(Tok::Word(vec![(r.style, w)])),
            }
        };
        for c in r.text.chars() {
            match c {
                ' ' => {
                    push_word(&mut toks, &mut word);
                    toks.push(Tok::Space(r.style));
                }
                '\n' => {
                    push_word(&mut toks, &mut word);
                    toks.push(Tok::Break);
                }
                c => word.push(c),
            }
        }
        push_word(&mut toks, &mut word);
    }
    let w_of = |style: Style, t: &str| m.width(t, piece_size(size, style), Face::of(style));
    let mut lines: Vec<Vec<Piece>> = vec![vec![]];
    let mut x = 0.0f32;
    let mut pending_space: Option<Style> = None;
    let add = |line: &mut Vec<Piece>, dx: f32, style: Style, text: &str| match line.last_mut() {
        Some(p) if p.style == style => p.text.push_str(text),
        _ => line.push(Piece {
            dx,
            style,
            text: text.to_string(),
        }),
    };
    for t in toks {
        match t {
            Tok::Break => {
                lines.push(vec![]);
                x = 0.0;
                pending_space = None;
            }
            Tok::Space(s) => pending_space = Some(s),
            Tok::Word(parts) => {
                let ww: f32 = parts.iter().map(|(s, t)| w_of(*s, t)).sum();
                let sw = pending_space.map_or(0.0, |s| w_of(s, " "));
                let line = lines.last_mut().expect("a line");
                if !line.is_empty() && x + sw + ww > width {
                    lines.push(vec![]);
                    x = 0.0;
                } else if let (false, Some(s)) = (line.is_empty(), pending_space) {
                    add(line, x, s, " ");
                    x += sw;
                }
                pending_space = None;
                for (s, text) in parts {
                    for c in text.chars() {
                        let mut buf = [0u8; 4];
                        let cs: &str = c.encode_utf8(&mut buf);
                        let cw = w_of(s, cs);
                        if x + cw > width && x > 0.0 && ww > width {
                            lines.push(vec![]);
                            x = 0.0;
                        }
                        add(lines.last_mut().expect("a line"), x, s, cs);
                        x += cw;
                    }
                }
            }
        }
    }
    if lines.last().is_some_and(Vec::is_empty) && lines.len() > 1 {
        lines.pop();
    }
    lines
}

/// The typeset document.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Layout {
    /// What each page shows, in order.
    pub pages: Vec<Vec<Item>>,
}

struct Setter<'a> {
    sheet: Sheet,
    m: &'a dyn Measure,
    pages: Vec<Vec<Item>>,
    y: f32,
    /// Where the laboratory's text starts when a logo stands left of it, and the logo's foot.
    beside_logo: Option<(f32, f32)>,
    /// The row of figures being set: how many it holds, how many it has, its top and foot.
    row: Option<(u8, u8, f32, f32)>,
    /// The column of that row the figure being set stands in: its left edge and width.
    column: Option<(f32, f32)>,
}

impl Setter<'_> {
    /// Starts a captioned figure `h` tall in a row of `across`: beside the row's last
    /// figure when there is room, else a new row (on a new page when it does not fit).
    fn cell(&mut self, across: u8, h: f32) {
        let w = self.sheet.measure() / f32::from(across);
        let row = match self.row {
            Some((n, k, top, foot)) if n == across && k < n && top + h <= self.sheet.foot() => {
                (n, k, top, foot)
            }
            _ => {
                self.need(h);
                (across, 0, self.y, self.y)
            }
        };
        self.y = row.2;
        self.column = Some((self.sheet.left + f32::from(row.1) * w, w));
        self.row = Some(row);
    }

    /// Ends the figure [`Setter::cell`] started: the text goes on below the row.
    fn end_cell(&mut self) {
        if let (Some((n, k, top, foot)), Some(_)) = (self.row, self.column.take()) {
            let foot = foot.max(self.y);
            self.row = Some((n, k + 1, top, foot));
            self.y = foot;
        }
    }
}

impl Setter<'_> {
    fn page(&mut self) -> &mut Vec<Item> {
        self.pages.last_mut().expect("a page")
    }

    fn new_page(&mut self) {
        self.pages.push(Vec::new());
        self.y = self.sheet.top;
    }

    fn room(&self) -> f32 {
        self.sheet.foot() - self.y
    }

    /// Starts a new page unless `h` fits below (or the page is still empty).
    fn need(&mut self, h: f32) {
        if h > self.room() && self.y > self.sheet.top + 0.5 {
            self.new_page();
        }
    }

    fn text_lines(&mut self, lines: &[Vec<Piece>], x: f32, size: f32) {
        let lead = size * LEADING;
        for line in lines {
            let base = self.y + size;
            for p in line {
                let s = piece_size(size, p.style);
                let drop = if p.style.sub { size * 0.2 } else { 0.0 };
                let item = Item::Text {
                    x: x + p.dx,
                    y: base + drop,
                    size: s,
                    face: Face::of(p.style),
                    colour: colour(p.style),
                    text: p.text.clone(),
                };
                self.page().push(item);
            }
            self.y += lead;
        }
    }
}

/// How a paragraph of `kind` is spaced: before, after.
fn spacing(kind: Kind) -> (f32, f32) {
    match kind {
        Kind::Heading(1) => (0.0, 4.0),
        Kind::Heading(2) => (10.0, 4.0),
        Kind::Heading(_) => (6.0, 2.0),
        Kind::Caption => (4.0, 2.0),
        Kind::Bullet => (0.0, 2.0),
        _ => (0.0, 4.0),
    }
}

/// Column widths for `rows` in `measure` points: each column's widest single line when they
/// fit, else each its longest word and the rest shared in proportion to what it lacks.
fn column_widths(rows: &[&Row], measure: f32, m: &dyn Measure) -> Vec<f32> {
    let n = rows.iter().map(|r| r.cells.len()).max().unwrap_or(0);
    let mut natural = vec![2.0 * PAD_X; n];
    let mut least = vec![2.0 * PAD_X; n];
    // Heading cells on one line where the measure allows.
    let mut heading = vec![2.0 * PAD_X; n];
    for r in rows {
        for (i, c) in r.cells.iter().enumerate() {
            let full: f32 = c
                .runs
                .iter()
                .map(|r| m.width(&r.text, piece_size(TABLE, r.style), Face::of(r.style)))
                .sum();
            let word = c
                .runs
                .iter()
                .flat_map(|r| {
                    r.text
                        .split(' ')
                        .map(move |w| m.width(w, piece_size(TABLE, r.style), Face::of(r.style)))
                })
                .fold(0.0f32, f32::max);
            natural[i] = natural[i].max(full + 2.0 * PAD_X + 0.5);
            least[i] = least[i].max(word + 2.0 * PAD_X + 0.5);
            if c.heading {
                heading[i] = heading[i].max(full + 2.0 * PAD_X + 0.5);
            }
        }
    }
    let unwrapped: Vec<f32> = least.iter().zip(&heading).map(|(l, h)| l.max(*h)).collect();
    if unwrapped.iter().sum::<f32>() <= measure {
        least = unwrapped;
    }
    let (sn, sl): (f32, f32) = (natural.iter().sum(), least.iter().sum());
    if sn <= measure {
        natural
    } else if sl <= measure {
        let share = (measure - sl) / (sn - sl);
        least
            .iter()
            .zip(&natural)
            .map(|(l, n)| l + (n - l) * share)
            .collect()
    } else {
        least.iter().map(|l| l * measure / sl).collect()
    }
}

/// A row set in its columns: each cell's lines, and the row's height.
fn set_row(row: &Row, widths: &[f32], m: &dyn Measure) -> (Vec<Vec<Vec<Piece>>>, f32) {
    let cells: Vec<Vec<Vec<Piece>>> = row
        .cells
        .iter()
        .zip(widths)
        .map(|(c, w)| wrap(&c.runs, TABLE, w - 2.0 * PAD_X, m))
        .collect();
    let lines = cells.iter().map(Vec::len).max().unwrap_or(1).max(1);
    let h = lines as f32 * TABLE * TABLE_LEADING + 2.0 * PAD_Y;
    (cells, if row.tall { h.max(2.6 * BODY) } else { h })
}

impl Setter<'_> {
    fn draw_row(&mut self, row: &Row, set: &(Vec<Vec<Vec<Piece>>>, f32), widths: &[f32]) {
        let x0 = self.sheet.left;
        let (cells, h) = set;
        let mut x = x0;
        for ((cell, lines), w) in row.cells.iter().zip(cells).zip(widths) {
            if cell.heading {
                let (y, w, h) = (self.y, *w, *h);
                self.page().push(Item::Fill {
                    x,
                    y,
                    w,
                    h,
                    colour: HEAD_FILL,
                });
            }
            let y = self.y;
            for (k, line) in lines.iter().enumerate() {
                let lw = line.last().map_or(0.0, |p| {
                    p.dx + self
                        .m
                        .width(&p.text, piece_size(TABLE, p.style), Face::of(p.style))
                });
                let left = if cell.left || cell_is_wide(cell) {
                    x + PAD_X
                } else {
                    x + w - PAD_X - lw
                };
                let base = y + PAD_Y + TABLE + k as f32 * TABLE * TABLE_LEADING;
                for p in line {
                    let drop = if p.style.sub { TABLE * 0.2 } else { 0.0 };
                    let item = Item::Text {
                        x: left + p.dx,
                        y: base + drop,
                        size: piece_size(TABLE, p.style),
                        face: Face::of(emboldened(p.style, cell.heading)),
                        colour: colour(p.style),
                        text: p.text.clone(),
                    };
                    self.page().push(item);
                }
            }
            x += w;
        }
        let right = x;
        let (top, bottom) = (self.y, self.y + h);
        let mut rules = vec![(x0, top, right, top), (x0, bottom, right, bottom)];
        let mut xs = x0;
        rules.push((xs, top, xs, bottom));
        for w in widths.iter().take(row.cells.len().max(1)) {
            xs += w;
            rules.push((xs, top, xs, bottom));
        }
        for (x1, y1, x2, y2) in rules {
            self.page().push(Item::Line {
                x1,
                y1,
                x2,
                y2,
                width: 0.4,
                colour: BORDER,
            });
        }
        self.y += h;
    }

    fn table(&mut self, head: &[Row], body: &[Row]) {
        let all: Vec<&Row> = head.iter().chain(body).collect();
        let widths = column_widths(&all, self.sheet.measure(), self.m);
        let head_set: Vec<_> = head.iter().map(|r| set_row(r, &widths, self.m)).collect();
        let head_h: f32 = head_set.iter().map(|s| s.1).sum();
        let body_set: Vec<_> = body.iter().map(|r| set_row(r, &widths, self.m)).collect();
        // A table of rows to sign in stays whole; any other starts where its heading and
        // first row fit.
        let whole = body.iter().any(|r| r.tall);
        let first = if whole {
            body_set.iter().map(|s| s.1).sum()
        } else {
            body_set.first().map_or(0.0, |s| s.1)
        };
        self.need(head_h + first);
        for (r, s) in head.iter().zip(&head_set) {
            self.draw_row(r, s, &widths);
        }
        for (r, s) in body.iter().zip(&body_set) {
            if s.1 > self.room() {
                self.new_page();
                for (hr, hs) in head.iter().zip(&head_set) {
                    self.draw_row(hr, hs, &widths);
                }
            }
            self.draw_row(r, s, &widths);
        }
        self.y += 6.0;
    }

    fn para(&mut self, kind: Kind, tone: Tone, runs: &[Run], keep: f32) {
        let size = size_of(kind);
        let bold = matches!(kind, Kind::Heading(_) | Kind::LabName | Kind::Caption);
        let (before, after) = spacing(kind);
        let bullet = kind == Kind::Bullet;
        let (left, measure) = self
            .column
            .unwrap_or((self.sheet.left, self.sheet.measure()));
        let mut x = left + if bullet { 10.0 } else { 0.0 };
        let mut width = measure - if bullet { 10.0 } else { 0.0 };
        if let Some((indent, _)) = self.beside_logo {
            x += indent;
            width -= indent;
        }
        let tone_c = tone_colours(tone);
        if tone_c.is_some() {
            x += TONE_INDENT;
            width -= TONE_INDENT + 4.0;
        }
        let runs: Vec<Run> = runs
            .iter()
            .map(|r| Run {
                text: r.text.clone(),
                style: emboldened(r.style, bold),
            })
            .collect();
        let lines = wrap(&runs, size, width, self.m);
        let lead = size * LEADING;
        let h: f32 = lines.len() as f32 * lead;
        let pad = if tone_c.is_some() { 2.0 } else { 0.0 };
        if self.y > self.sheet.top + 0.5 {
            self.y += before;
        }
        // Whole when short, else at least two lines on this page.
        let first = if lines.len() <= 3 { h } else { 2.0 * lead };
        self.need(first + 2.0 * pad + keep);
        let mut start = 0;
        while start < lines.len() {
            let fit = (((self.room() - 2.0 * pad) / lead).floor() as usize).max(1);
            let end = (start + fit).min(lines.len());
            let top = self.y;
            let block_h = (end - start) as f32 * lead + 2.0 * pad;
            if let Some((bar, fill)) = tone_c {
                let left = x - TONE_INDENT;
                let w = width + TONE_INDENT + 4.0;
                self.page().push(Item::Fill {
                    x: left,
                    y: top,
                    w,
                    h: block_h + after,
                    colour: fill,
                });
                self.page().push(Item::Fill {
                    x: left,
                    y: top,
                    w: 3.0,
                    h: block_h + after,
                    colour: bar,
                });
            }
            self.y += pad;
            if bullet && start == 0 {
                let item = Item::Text {
                    x: x - 8.0,
                    y: self.y + size,
                    size,
                    face: Face::Regular,
                    colour: INK,
                    text: "•".into(),
                };
                self.page().push(item);
            }
            self.text_lines(&lines[start..end], x, size);
            self.y += pad;
            start = end;
            if start < lines.len() {
                self.new_page();
            }
        }
        if kind == Kind::Heading(2) {
            let (l, r, y) = (
                self.sheet.left,
                self.sheet.width - self.sheet.right,
                self.y + 1.0,
            );
            self.page().push(Item::Line {
                x1: l,
                y1: y,
                x2: r,
                y2: y,
                width: 0.6,
                colour: BORDER,
            });
        }
        self.y += after;
    }

    /// Image `index`, as wide as one of `across` figures in a row (set one under another).
    fn image(&mut self, index: usize, size: &ImageSize, logo: bool, across: u8) {
        let (w0, h0) = match size {
            Ok(s) if s.0 > 0.0 && s.1 > 0.0 => *s,
            // A logo that cannot be drawn is left out (the caller says so).
            _ if logo => return,
            Ok(_) => return,
            Err(e) => {
                let runs = [Run {
                    text: format!("This figure cannot be drawn: {e}."),
                    style: Style {
                        muted: true,
                        ..Style::default()
                    },
                }];
                self.para(Kind::Body, Tone::Plain, &runs, 0.0);
                return;
            }
        };
        let (left, measure) = self
            .column
            .unwrap_or((self.sheet.left, self.sheet.measure()));
        let (max_w, max_h) = if logo {
            LOGO_MAX
        } else {
            (
                measure.min(self.sheet.measure() / f32::from(across).max(1.0)),
                FIGURE_MAX_H.min(self.sheet.foot() - self.sheet.top),
            )
        };
        let scale = (max_w / w0).min(max_h / h0);
        let (w, h) = (w0 * scale, h0 * scale);
        if logo {
            let (x, y) = (self.sheet.left, self.y);
            self.page().push(Item::Image { index, x, y, w, h });
            self.beside_logo = Some((w + 10.0, y + h));
            return;
        }
        self.need(h);
        let (x, y) = (left, self.y);
        self.page().push(Item::Image { index, x, y, w, h });
        self.y += h + 8.0;
    }

    fn rule(&mut self) {
        if let Some((_, foot)) = self.beside_logo.take() {
            self.y = self.y.max(foot);
        }
        self.y += 3.0;
        let (l, r, y) = (self.sheet.left, self.sheet.width - self.sheet.right, self.y);
        self.page().push(Item::Line {
            x1: l,
            y1: y,
            x2: r,
            y2: y,
            width: 0.6,
            colour: (0x99, 0x99, 0x99),
        });
        self.y += 8.0;
    }
}

/// A cell whose text is long prose (a key–value table's value) reads from the left.
fn cell_is_wide(cell: &Cell) -> bool {
    cell.runs.iter().map(|r| r.text.len()).sum::<usize>() > 40
}

/// What must fit below a heading or caption with it: the first line of a paragraph, a
/// table's heading rows and first row, a whole figure.
fn lead(blocks: &[Block], sizes: &mut dyn Iterator<Item = &ImageSize>, measure: f32) -> f32 {
    match blocks.first() {
        // A heading or caption goes with what follows it (a heading before a figure's
        // caption: the figure too).
        Some(Block::Para {
            kind: kind @ (Kind::Heading(_) | Kind::Caption),
            ..
        }) => size_of(*kind) * LEADING * 2.0 + lead(&blocks[1..], sizes, measure),
        Some(Block::Para { kind, .. }) => size_of(*kind) * LEADING * 2.0,
        Some(Block::Table { head, body, .. }) if body.iter().any(|r| r.tall) => {
            head.len() as f32 * (TABLE * TABLE_LEADING + 2.0 * PAD_Y)
                + body.len() as f32 * 2.6 * BODY
        }
        Some(Block::Table { head, body, .. }) => {
            (head.len() + body.len().min(1)) as f32 * (TABLE * TABLE_LEADING * 2.0 + 2.0 * PAD_Y)
        }
        Some(Block::Image {
            logo: false,
            across,
            ..
        }) => match sizes.next() {
            Some(Ok((w, h))) if *w > 0.0 => {
                (h * (measure / f32::from(*across).max(1.0) / w)).min(FIGURE_MAX_H)
            }
            _ => 0.0,
        },
        _ => 0.0,
    }
}

/// Sets `blocks` on pages of `sheet`; `images` gives the size of each image block in order.
pub fn typeset(
    blocks: &[Block],
    images: &[ImageSize],
    sheet: Sheet,
    running: &Running,
    m: &dyn Measure,
) -> Layout {
    let mut s = Setter {
        sheet,
        m,
        pages: vec![Vec::new()],
        y: sheet.top,
        beside_logo: None,
        row: None,
        column: None,
    };
    let mut image = 0usize;
    for (i, b) in blocks.iter().enumerate() {
        // A captioned figure of a row of several: set in its column, beside the one before.
        if let (
            Block::Para {
                kind: Kind::Caption,
                runs,
                ..
            },
            Some(Block::Image {
                logo: false,
                across: 2..,
                ..
            }),
        ) = (b, blocks.get(i + 1))
        {
            let mut rest = images[image..].iter();
            let h = lead(&blocks[i + 1..], &mut rest, sheet.measure());
            let caption = wrap(runs, BODY, sheet.measure(), m).len() as f32 * BODY * LEADING;
            if let Some(Block::Image { across, .. }) = blocks.get(i + 1) {
                s.cell(*across, caption * 2.0 + h + 14.0);
            }
        } else if !matches!(b, Block::Image { across: 2.., .. }) {
            s.row = None;
        }
        match b {
            Block::Para { kind, tone, runs } => {
                let keep = match kind {
                    Kind::Heading(_) | Kind::Caption => {
                        let mut rest = images[image..].iter();
                        lead(&blocks[i + 1..], &mut rest, sheet.measure())
                    }
                    _ => 0.0,
                };
                s.para(*kind, *tone, runs, keep);
            }
            Block::Table { head, body, .. } => s.table(head, body),
            Block::Image { logo, across, .. } => {
                let size = images.get(image).cloned().unwrap_or(Ok((0.0, 0.0)));
                s.image(image, &size, *logo, *across);
                s.end_cell();
                image += 1;
            }
            Block::Rule => s.rule(),
        }
    }
    let total = s.pages.len();
    for (k, page) in s.pages.iter_mut().enumerate() {
        running_items(page, &sheet, running, k + 1, total, m);
    }
    Layout { pages: s.pages }
}

/// The running header and footer of page `n` of `total`.
fn running_items(
    page: &mut Vec<Item>,
    sheet: &Sheet,
    running: &Running,
    n: usize,
    total: usize,
    m: &dyn Measure,
) {
    let right = sheet.width - sheet.right;
    // Baselines 6 mm above and 8 mm below the text block; in Letter's narrower margins no
    // nearer the paper's edge than 8.5 and 7 mm, so that the letters (ascenders above the
    // header's baseline, descenders below the footer's) stay 5 mm or more from it, clear of
    // the 4 mm or so a printer leaves unprinted.
    let top = sheet.top - (6.0 * MM).min(sheet.top - 8.5 * MM);
    let foot = sheet.height - sheet.bottom + (8.0 * MM).min(sheet.bottom - 7.0 * MM);
    let number = format!("page {n} of {total}");
    let mut text = |x: f32, y: f32, size: f32, t: &str| {
        page.push(Item::Text {
            x,
            y,
            size,
            face: Face::Regular,
            colour: MUTED,
            text: t.to_string(),
        })
    };
    text(sheet.left, top, 8.0, &running.top_left);
    let w = m.width(&running.top_right, 8.0, Face::Regular);
    let room = right - sheet.left - m.width(&running.top_left, 8.0, Face::Regular) - 12.0;
    if w <= room {
        text(right - w, top, 8.0, &running.top_right);
    }
    text(sheet.left, foot, 7.0, &running.bottom_left);
    text(
        right - m.width(&number, 8.0, Face::Regular),
        foot,
        8.0,
        &number,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every character 0.5 em wide.
    struct Mono;
    impl Measure for Mono {
        fn width(&self, text: &str, size: f32, _: Face) -> f32 {
            text.chars().count() as f32 * size * 0.5
        }
    }

    fn run(t: &str) -> Run {
        Run {
            text: t.into(),
            style: Style::default(),
        }
    }

    fn texts(page: &[Item]) -> Vec<&str> {
        page.iter()
            .filter_map(|i| match i {
                Item::Text { text, .. } => Some(text.as_str()),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn lines_break_at_spaces_and_inside_a_word_only_when_it_is_wider_than_the_line() {
        // 10 pt: 5 pt a character; 50 pt is ten characters.
        let lines = wrap(&[run("aaaa bbbb cccc")], 10.0, 50.0, &Mono);
        let text: Vec<String> = lines
            .iter()
            .map(|l| l.iter().map(|p| p.text.as_str()).collect())
            .collect();
        assert_eq!(text, ["aaaa bbbb", "cccc"]);
        let long = wrap(&[run("abcdefghijklmnop")], 10.0, 50.0, &Mono);
        assert_eq!(long.len(), 2);
        assert_eq!(long[0][0].text, "abcdefghij");
        // A word across two styles stays one word; its second piece starts where the first
        // ends.
        let bold = Style {
            bold: true,
            ..Style::default()
        };
        let l = wrap(
            &[
                run("x u"),
                Run {
                    text: "c".into(),
                    style: bold,
                },
            ],
            10.0,
            500.0,
            &Mono,
        );
        assert_eq!(l.len(), 1);
        assert_eq!((l[0][1].dx, l[0][1].text.as_str()), (15.0, "c"));
    }

    #[test]
    fn a_long_table_runs_over_pages_with_its_heading_repeated_and_numbered_pages() {
        let cell = |t: &str, heading| Cell {
            runs: vec![run(t)],
            heading,
            left: false,
        };
        let head = vec![Row {
            cells: vec![cell("line", true), cell("Ra µm", true)],
            tall: false,
        }];
        let body: Vec<Row> = (0..200)
            .map(|k| Row {
                cells: vec![cell(&format!("L{k}"), false), cell("1.0", false)],
                tall: false,
            })
            .collect();
        let blocks = vec![Block::Table {
            id: "t".into(),
            head,
            body,
        }];
        let running = Running {
            top_left: "Lab".into(),
            top_right: "scan".into(),
            bottom_left: "by".into(),
        };
        let l = typeset(&blocks, &[], Sheet::new(false), &running, &Mono);
        assert!(l.pages.len() >= 3, "{}", l.pages.len());
        let n = l.pages.len();
        let mut rows = 0;
        for (k, p) in l.pages.iter().enumerate() {
            let t = texts(p);
            assert_eq!(t.iter().filter(|t| **t == "Ra µm").count(), 1, "page {k}");
            assert!(t.contains(&format!("page {} of {n}", k + 1).as_str()));
            rows += t
                .iter()
                .filter(|t| t.starts_with('L') && **t != "Lab")
                .count();
            // Nothing below the bottom margin but the footer.
            for i in p {
                if let Item::Text { y, text, .. } = i {
                    assert!(
                        *y <= Sheet::new(false).foot() || text == "by" || text.starts_with("page"),
                        "{text} at {y}"
                    );
                }
            }
        }
        assert_eq!(rows, 200);
    }

    #[test]
    fn columns_keep_their_natural_width_when_they_fit_and_share_the_measure_when_not() {
        let row = |a: &str, b: &str| Row {
            cells: vec![
                Cell {
                    runs: vec![run(a)],
                    ..Cell::default()
                },
                Cell {
                    runs: vec![run(b)],
                    ..Cell::default()
                },
            ],
            tall: false,
        };
        let short = row("ab", "cd");
        let w = column_widths(&[&short], 500.0, &Mono);
        let natural = 2.0 * 3.75 + 2.0 * PAD_X + 0.5;
        assert!(
            (w[0] - natural).abs() < 1e-4 && (w[1] - natural).abs() < 1e-4,
            "{w:?}"
        );
        let long = row("key", &"word ".repeat(100));
        let w = column_widths(&[&long], 300.0, &Mono);
        assert!((w.iter().sum::<f32>() - 300.0).abs() < 1e-3, "{w:?}");
        assert!(w[0] >= 3.0 * 3.75 + 2.0 * PAD_X, "{w:?}");
        // A heading is kept on one line while the measure allows: its column is at least as
        // wide as the heading, not only its longest word.
        let mut head = row("U of a line %", "why");
        head.cells[0].heading = true;
        let w = column_widths(&[&head, &long], 300.0, &Mono);
        assert!(w[0] >= 13.0 * 3.75 + 2.0 * PAD_X, "{w:?}");
        assert!((w.iter().sum::<f32>() - 300.0).abs() < 1e-3, "{w:?}");
    }

    #[test]
    fn a_heading_moves_to_the_next_page_with_the_table_it_heads() {
        // 44 paragraphs leave room for the heading but not for the rows to sign in.
        let mut blocks: Vec<Block> = (0..44)
            .map(|k| Block::Para {
                kind: Kind::Body,
                tone: Tone::Plain,
                runs: vec![run(&format!("p{k}"))],
            })
            .collect();
        blocks.push(Block::Para {
            kind: Kind::Heading(2),
            tone: Tone::Plain,
            runs: vec![run("Approval")],
        });
        let sign = Row {
            cells: vec![Cell {
                runs: vec![run("Approved by")],
                ..Cell::default()
            }],
            tall: true,
        };
        blocks.push(Block::Table {
            id: "s".into(),
            head: vec![],
            body: vec![sign.clone(), sign.clone(), sign],
        });
        let l = typeset(&blocks, &[], Sheet::new(false), &Running::default(), &Mono);
        let page_of = |t: &str| l.pages.iter().position(|p| texts(p).contains(&t)).unwrap();
        assert_eq!(page_of("Approval"), page_of("Approved by"));
    }

    #[test]
    fn a_heading_before_a_captioned_figure_moves_with_the_figure() {
        // 44 paragraphs leave room for the heading and the caption, not for the figure.
        let para = |kind, t: &str| Block::Para {
            kind,
            tone: Tone::Plain,
            runs: vec![run(t)],
        };
        let mut blocks: Vec<Block> = (0..44)
            .map(|k| para(Kind::Body, &format!("p{k}")))
            .collect();
        blocks.push(para(Kind::Heading(2), "Plots"));
        blocks.push(para(Kind::Caption, "Measured heights"));
        blocks.push(Block::Image {
            image: super::super::markup::Image {
                media_type: "image/png".into(),
                bytes: vec![],
            },
            logo: false,
            across: 1,
        });
        let sizes = [Ok((400.0, 200.0))];
        let l = typeset(
            &blocks,
            &sizes,
            Sheet::new(false),
            &Running::default(),
            &Mono,
        );
        let page_of = |t: &str| l.pages.iter().position(|p| texts(p).contains(&t)).unwrap();
        let figure = (l.pages.iter())
            .position(|p| p.iter().any(|i| matches!(i, Item::Image { .. })))
            .unwrap();
        assert_eq!(page_of("p0"), 0);
        assert_eq!(
            (page_of("Plots"), page_of("Measured heights")),
            (figure, figure)
        );
        assert_eq!(figure, 1, "the figure does not fit under the paragraphs");
    }
}
