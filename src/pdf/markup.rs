//! The page a report's HTML renderer writes, read back as blocks to typeset: headings,
//! paragraphs, list items, tables (their heading rows apart) and figures. It reads the
//! subset that renderer writes (well-formed, attribute values quoted, text escaped) as a
//! browser prints it: what print hides (`<details>` but those of class `print`, whose
//! summary is a caption; `.noprint`; the `<head>`) is left out.
//!
//! Pure: text in, blocks out. Depends on nothing but `base64` (the embedded figures).

use base64::Engine as _;

/// How a run of text is set.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Style {
    /// Bold (`<b>`, `<th>`, headings, captions).
    pub bold: bool,
    /// Grey (`.muted`).
    pub muted: bool,
    /// Red (`.flag`).
    pub flag: bool,
    /// Subscript (`<sub>`).
    pub sub: bool,
    /// Monospaced (`<code>`, `<kbd>`, `<samp>`): hashes and identifiers.
    pub mono: bool,
}

/// Text with one style.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// What it says.
    pub text: String,
    /// How.
    pub style: Style,
}

/// What a paragraph is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Body text.
    Body,
    /// A heading of level 1 to 3.
    Heading(u8),
    /// The laboratory's name atop the report.
    LabName,
    /// A list item.
    Bullet,
    /// A figure's caption.
    Caption,
}

/// The coloured bar a paragraph or list stands behind (`.warn`, `.ok`, `.bad`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tone {
    /// None.
    Plain,
    /// A warning (orange).
    Warn,
    /// A good result (green).
    Ok,
    /// A bad one (red).
    Bad,
}

/// A table cell.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Cell {
    /// Its text.
    pub runs: Vec<Run>,
    /// A heading cell (`<th>`).
    pub heading: bool,
    /// Aligned left (`class="t"`); numbers align right.
    pub left: bool,
}

/// A table row.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Row {
    /// Its cells, left to right.
    pub cells: Vec<Cell>,
    /// A row with room to sign in (`class="sign"`).
    pub tall: bool,
}

/// An image's bytes and media type.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// `image/svg+xml`, `image/png`, `image/jpeg`.
    pub media_type: String,
    /// The file's bytes.
    pub bytes: Vec<u8>,
}

/// One block of the page, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Block {
    /// Text that wraps.
    #[allow(missing_docs)]
    Para {
        kind: Kind,
        tone: Tone,
        runs: Vec<Run>,
    },
    /// A table: the heading rows repeat on every page it runs onto.
    #[allow(missing_docs)]
    Table {
        id: String,
        head: Vec<Row>,
        body: Vec<Row>,
    },
    /// An image: a figure, or the laboratory's logo; `across` figures share a printed row
    /// (3 beside the areal parameters, 3 of the per-line figures, else 1).
    #[allow(missing_docs)]
    Image {
        image: Image,
        logo: bool,
        across: u8,
    },
    /// A rule under the laboratory's header.
    Rule,
}

/// One tag of the page.
struct Tag<'a> {
    name: String,
    closing: bool,
    attrs: &'a str,
}

impl Tag<'_> {
    fn attr(&self, name: &str) -> Option<String> {
        let mut rest = self.attrs;
        while let Some(eq) = rest.find("=\"") {
            let key = rest[..eq].trim();
            let after = &rest[eq + 2..];
            let end = after.find('"')?;
            if key == name {
                return Some(decode(&after[..end]));
            }
            rest = &after[end + 1..];
        }
        None
    }

    fn has_class(&self, class: &str) -> bool {
        self.attr("class")
            .is_some_and(|c| c.split_whitespace().any(|c| c == class))
    }
}

/// Text with its character references replaced (the five the renderer writes and numeric
/// ones).
pub fn decode(s: &str) -> String {
    if !s.contains('&') {
        return s.to_string();
    }
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find('&') {
        out.push_str(&rest[..i]);
        rest = &rest[i..];
        let Some(end) = rest.find(';').filter(|&e| e <= 10) else {
            out.push('&');
            rest = &rest[1..];
            continue;
        };
        let name = &rest[1..end];
        let c = match name {
            "amp" => Some('&'),
            "lt" => Some('<'),
            "gt" => Some('>'),
            "quot" => Some('"'),
            "apos" => Some('\''),
            "nbsp" => Some('\u{a0}'),
            _ => name
                .strip_prefix("#x")
                .map(|h| u32::from_str_radix(h, 16).ok())
                .unwrap_or_else(|| name.strip_prefix('#').and_then(|d| d.parse().ok()))
                .and_then(char::from_u32),
        };
        match c {
            Some(c) => {
                out.push(c);
                rest = &rest[end + 1..];
            }
            None => {
                out.push('&');
                rest = &rest[1..];
            }
        }
    }
    out.push_str(rest);
    out
}

/// The page's tags and texts in order.
fn tokens(html: &str) -> impl Iterator<Item = Result<Tag<'_>, &str>> {
    let mut rest = html;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        if let Some(body) = rest.strip_prefix('<') {
            let end = body.find('>').unwrap_or(body.len());
            let inner = &body[..end];
            rest = body.get(end + 1..).unwrap_or("");
            let closing = inner.starts_with('/');
            let inner = inner.trim_start_matches(['/', '!']);
            let name_end = inner
                .find(|c: char| c.is_whitespace() || c == '/')
                .unwrap_or(inner.len());
            return Some(Ok(Tag {
                name: inner[..name_end].to_ascii_lowercase(),
                closing,
                attrs: &inner[name_end..],
            }));
        }
        let end = rest.find('<').unwrap_or(rest.len());
        let text = &rest[..end];
        rest = &rest[end..];
        Some(Err(text))
    })
}

const VOID: &[&str] = &["meta", "img", "br", "hr", "link", "input", "doctype"];

/// Reads the blocks of `html` as print shows them.
pub fn blocks(html: &str) -> Vec<Block> {
    let mut b = Builder::default();
    for token in tokens(html) {
        match token {
            Err(text) => b.text(text),
            Ok(tag) if tag.closing => b.close(&tag.name),
            Ok(tag) => b.open(&tag),
        }
    }
    b.flush();
    b.out
}

#[derive(Default)]
struct Builder {
    out: Vec<Block>,
    /// The open elements: name, the style they set, whether they hide what is inside.
    open: Vec<(String, Style, bool, Tone)>,
    runs: Vec<Run>,
    kind: Option<Kind>,
    table: Option<(String, Vec<Row>, Vec<Row>, bool)>,
    row: Option<Row>,
    cell: Option<Cell>,
    /// The open rows of figures: where in `open` each began, how many figures it holds.
    rows: Vec<(usize, u8)>,
}

impl Builder {
    fn hidden(&self) -> bool {
        self.open.iter().any(|(_, _, h, _)| *h)
    }

    fn style(&self) -> Style {
        self.open
            .iter()
            .fold(Style::default(), |s, (_, o, _, _)| Style {
                bold: s.bold || o.bold,
                muted: s.muted || o.muted,
                flag: s.flag || o.flag,
                sub: s.sub || o.sub,
                mono: s.mono || o.mono,
            })
    }

    fn tone(&self) -> Tone {
        self.open
            .iter()
            .rev()
            .map(|(_, _, _, t)| *t)
            .find(|t| *t != Tone::Plain)
            .unwrap_or(Tone::Plain)
    }

    fn text(&mut self, raw: &str) {
        if self.hidden() || self.open.iter().any(|(n, ..)| n == "head") {
            return;
        }
        let text = decode(raw);
        let mut collapsed = String::with_capacity(text.len());
        let mut space = false;
        for c in text.chars() {
            if c.is_whitespace() && c != '\u{a0}' {
                space = true;
            } else {
                if space {
                    collapsed.push(' ');
                }
                space = false;
                collapsed.push(c);
            }
        }
        if space {
            collapsed.push(' ');
        }
        if collapsed.is_empty() || (collapsed == " " && self.cell.is_none() && self.runs.is_empty())
        {
            return;
        }
        let run = Run {
            text: collapsed,
            style: self.style(),
        };
        match &mut self.cell {
            Some(c) => c.runs.push(run),
            None if self.table.is_some() => {}
            None => self.runs.push(run),
        }
    }

    /// Ends the paragraph being gathered.
    fn flush(&mut self) {
        let runs = trim(std::mem::take(&mut self.runs));
        let kind = self.kind.take().unwrap_or(Kind::Body);
        if !runs.is_empty() {
            self.out.push(Block::Para {
                kind,
                tone: self.tone(),
                runs,
            });
        }
    }

    fn open(&mut self, tag: &Tag<'_>) {
        let name = tag.name.as_str();
        let hides = self.hidden()
            || matches!(name, "head" | "script" | "style" | "title")
            || (name == "details" && !tag.has_class("print"))
            || tag.has_class("noprint");
        let mut style = Style::default();
        match name {
            "b" | "strong" | "th" | "figcaption" | "summary" => style.bold = true,
            "sub" => style.sub = true,
            "code" | "kbd" | "samp" => style.mono = true,
            _ => {}
        }
        if name == "div" && tag.has_class("lab-name") {
            style.bold = true;
        }
        style.muted = tag.has_class("muted");
        style.flag = tag.has_class("flag");
        let tone = match () {
            _ if tag.has_class("warn") => Tone::Warn,
            _ if tag.has_class("bad") => Tone::Bad,
            _ if tag.has_class("ok") => Tone::Ok,
            _ => Tone::Plain,
        };
        if !hides {
            self.block_start(tag);
        }
        let across = match name {
            "div" if tag.has_class("areal-figures") => 3,
            "details" if tag.has_class("print") => 3,
            _ => 0,
        };
        if across > 0 {
            self.rows.push((self.open.len(), across));
        }
        if !VOID.contains(&name) {
            self.open.push((tag.name.clone(), style, hides, tone));
        }
    }

    fn block_start(&mut self, tag: &Tag<'_>) {
        let name = tag.name.as_str();
        match name {
            "h1" | "h2" | "h3" | "h4" | "p" | "li" | "div" | "figcaption" | "summary" | "ul"
            | "ol" | "figure" | "section" | "header" => {
                self.flush();
                self.kind = match name {
                    "h1" => Some(Kind::Heading(1)),
                    "h2" => Some(Kind::Heading(2)),
                    "h3" | "h4" => Some(Kind::Heading(3)),
                    "li" => Some(Kind::Bullet),
                    "figcaption" | "summary" => Some(Kind::Caption),
                    "div" if tag.has_class("lab-name") => Some(Kind::LabName),
                    _ => None,
                };
            }
            "br" => self.text("\n"),
            "table" => {
                self.flush();
                self.table = Some((tag.attr("id").unwrap_or_default(), vec![], vec![], false));
            }
            "thead" => {
                if let Some(t) = &mut self.table {
                    t.3 = true;
                }
            }
            "tr" => {
                self.row = Some(Row {
                    cells: vec![],
                    tall: tag.has_class("sign"),
                })
            }
            "td" | "th" => {
                self.cell = Some(Cell {
                    runs: vec![],
                    heading: name == "th",
                    left: tag.has_class("t"),
                })
            }
            "img" => {
                self.flush();
                if let Some(image) = tag.attr("src").and_then(|s| data_uri(&s)) {
                    self.out.push(Block::Image {
                        image,
                        logo: tag.has_class("logo"),
                        across: self.rows.last().map_or(1, |r| r.1),
                    });
                }
            }
            _ => {}
        }
    }

    fn close(&mut self, name: &str) {
        let Some(at) = self.open.iter().rposition(|(n, ..)| n == name) else {
            return;
        };
        let hidden = self.hidden();
        if !hidden {
            self.block_end(name);
        }
        self.open.truncate(at);
        self.rows.retain(|r| r.0 < at);
    }

    fn block_end(&mut self, name: &str) {
        match name {
            "td" | "th" => {
                if let (Some(mut c), Some(r)) = (self.cell.take(), &mut self.row) {
                    c.runs = trim(c.runs);
                    r.cells.push(c);
                }
            }
            "tr" => {
                if let (Some(r), Some(t)) = (self.row.take(), &mut self.table) {
                    // Heading rows: those of <thead>, or all-heading rows before any other.
                    let heading = t.3 || (t.2.is_empty() && r.cells.iter().all(|c| c.heading));
                    if heading {
                        t.1.push(r);
                    } else {
                        t.2.push(r);
                    }
                }
            }
            "thead" => {
                if let Some(t) = &mut self.table {
                    t.3 = false;
                }
            }
            "table" => {
                if let Some((id, head, body, _)) = self.table.take() {
                    self.out.push(Block::Table { id, head, body });
                }
            }
            "header" => {
                self.flush();
                self.out.push(Block::Rule);
            }
            "h1" | "h2" | "h3" | "h4" | "p" | "li" | "div" | "figcaption" | "ul" | "ol"
            | "figure" | "section" => self.flush(),
            _ => {}
        }
    }
}

/// The runs without the spaces at either end, runs left empty dropped.
fn trim(mut runs: Vec<Run>) -> Vec<Run> {
    if let Some(r) = runs.first_mut() {
        r.text = r.text.trim_start_matches(' ').to_string();
    }
    if let Some(r) = runs.last_mut() {
        r.text = r.text.trim_end_matches(' ').to_string();
    }
    runs.retain(|r| !r.text.is_empty());
    runs
}

/// The bytes of a `data:` URI in base64.
fn data_uri(src: &str) -> Option<Image> {
    let rest = src.strip_prefix("data:")?;
    let (media_type, data) = rest.split_once(";base64,")?;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(data.trim())
        .ok()?;
    Some(Image {
        media_type: media_type.to_string(),
        bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texts(b: &Block) -> String {
        match b {
            Block::Para { runs, .. } => runs.iter().map(|r| r.text.as_str()).collect(),
            _ => String::new(),
        }
    }

    #[test]
    fn references_are_decoded_and_unknown_ones_kept() {
        assert_eq!(
            decode("a &lt;b&gt; &amp; &#39;c&#39; &#xb5;m &quot;"),
            "a <b> & 'c' µm \""
        );
        assert_eq!(decode("R&D; 5 & 6 &bogus;"), "R&D; 5 & 6 &bogus;");
    }

    #[test]
    fn print_leaves_out_what_it_hides_and_keeps_the_order() {
        let html = "<html><head><title>T</title><style>p{}</style></head><body>\
<h1>Report</h1><p class=\"muted\">in   <b>bold</b>\n text</p>\
<details><summary>hidden</summary><p>hidden too</p></details>\
<p class=\"noprint\">screen only</p><div class=\"warn\"><ul><li>first</li><li>u<sub>c</sub></li></ul></div>\
<details class=\"print\"><summary>Line 1</summary><p>sha256 <code>ab12</code></p></details></body></html>";
        let b = blocks(html);
        let t: Vec<String> = b.iter().map(texts).collect();
        assert_eq!(
            t,
            [
                "Report",
                "in bold text",
                "first",
                "uc",
                "Line 1",
                "sha256 ab12"
            ]
        );
        // A details element print shows: its summary is a caption, its content is read.
        assert!(matches!(
            b[4],
            Block::Para {
                kind: Kind::Caption,
                ..
            }
        ));
        let Block::Para { runs, .. } = &b[5] else {
            panic!()
        };
        assert_eq!(
            runs.iter()
                .map(|r| (r.text.as_str(), r.style.mono))
                .collect::<Vec<_>>(),
            [("sha256 ", false), ("ab12", true)]
        );
        let Block::Para { kind, runs, .. } = &b[1] else {
            panic!()
        };
        assert_eq!(*kind, Kind::Body);
        assert!(runs.iter().all(|r| r.style.muted));
        assert_eq!(runs.iter().filter(|r| r.style.bold).count(), 1);
        assert!(matches!(
            b[0],
            Block::Para {
                kind: Kind::Heading(1),
                ..
            }
        ));
        assert!(matches!(
            b[3],
            Block::Para {
                kind: Kind::Bullet,
                tone: Tone::Warn,
                ..
            }
        ));
    }

    #[test]
    fn heading_rows_are_told_apart_from_the_body() {
        let html = "<table id=\"a\"><thead><tr><th>x</th><th>y</th></tr></thead>\
<tr><td class=\"t\">1</td><td>2 <span class=\"muted\">m</span></td></tr></table>\
<table id=\"b\"><tr><th>p</th><th>q</th></tr><tr><th class=\"t\">k</th><td>v</td></tr>\
<tr class=\"sign\"><td>s</td></tr></table>";
        let b = blocks(html);
        let [Block::Table { id, head, body }, Block::Table {
            head: h2, body: b2, ..
        }] = &b[..]
        else {
            panic!("{b:?}")
        };
        assert_eq!((id.as_str(), head.len(), body.len()), ("a", 1, 1));
        assert!(body[0].cells[0].left && !body[0].cells[1].left);
        assert_eq!(body[0].cells[1].runs.len(), 2);
        assert!(body[0].cells[1].runs[1].style.muted);
        assert_eq!((h2.len(), b2.len()), (1, 2));
        assert!(b2[1].tall && !b2[0].tall);
    }

    #[test]
    fn embedded_images_are_decoded() {
        let b = blocks("<figure><figcaption>Map</figcaption><img alt=\"Map\" src=\"data:image/svg+xml;base64,PHN2Zy8+\"></figure>");
        assert_eq!(texts(&b[0]), "Map");
        assert_eq!(
            b[1],
            Block::Image {
                image: Image {
                    media_type: "image/svg+xml".into(),
                    bytes: b"<svg/>".to_vec()
                },
                logo: false,
                across: 1
            }
        );
        let b = blocks("<div class=\"areal-figures\"><figure><img src=\"data:image/svg+xml;base64,PHN2Zy8+\"></figure></div><img src=\"data:image/svg+xml;base64,PHN2Zy8+\">");
        let across: Vec<u8> = (b.iter())
            .filter_map(|b| match b {
                Block::Image { across, .. } => Some(*across),
                _ => None,
            })
            .collect();
        assert_eq!(across, [3, 1], "a row of three, then a figure of its own");
    }
}
