//! A report page: a title, then sections of paragraphs, lists, notes, tables and SVG
//! figures, rendered to one self-contained HTML file (inline CSS, no JavaScript, no
//! external assets). All text is escaped; only figures' SVG goes in verbatim.

use std::path::Path;

use super::{Color, ReportError, escape_html, format_number};

/// One table cell: text, optionally on a background colour (heat tables), bold and
/// outlined (`strong`), right-aligned in tabular figures (`numeric`), or a row heading.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Cell {
    pub text: String,
    pub background: Option<Color>,
    pub strong: bool,
    pub numeric: bool,
    pub row_heading: bool,
}

impl Cell {
    pub fn new(text: impl Into<String>) -> Self {
        Cell { text: text.into(), ..Default::default() }
    }

    /// A right-aligned number cell.
    pub fn number(text: impl Into<String>) -> Self {
        Cell { numeric: true, ..Cell::new(text) }
    }

    /// A row's heading (`<th scope="row">`).
    pub fn heading(text: impl Into<String>) -> Self {
        Cell { row_heading: true, ..Cell::new(text) }
    }

    /// `value` to `decimals` places on the [`Color::diverging`] colour of `lo..hi`; "—"
    /// without colour when it is not finite.
    pub fn heat(value: f64, lo: f64, hi: f64, decimals: usize) -> Self {
        let text = if value.is_finite() { format!("{value:.decimals$}") } else { "—".into() };
        Cell { background: Color::diverging(value, lo, hi), ..Cell::number(text) }
    }

    pub fn on(mut self, background: Color) -> Self {
        self.background = Some(background);
        self
    }

    pub fn strong(mut self) -> Self {
        self.strong = true;
        self
    }

    fn to_html(&self, out: &mut String) {
        let tag = if self.row_heading { "th" } else { "td" };
        let mut classes = Vec::new();
        if self.numeric {
            classes.push("num");
        }
        if self.strong {
            classes.push("strong");
        }
        out.push('<');
        out.push_str(tag);
        if self.row_heading {
            out.push_str(" scope=\"row\"");
        }
        if !classes.is_empty() {
            out.push_str(&format!(" class=\"{}\"", classes.join(" ")));
        }
        if let Some(bg) = self.background {
            let fg = if bg.is_light() { "#111" } else { "#fff" };
            out.push_str(&format!(" style=\"background:{};color:{fg}\"", bg.hex()));
        }
        out.push('>');
        out.push_str(&escape_html(&self.text));
        out.push_str(&format!("</{tag}>"));
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Block {
    Paragraph(String),
    Note(String),
    List(Vec<String>),
    Table { header: Vec<String>, rows: Vec<Vec<Cell>> },
    Figure { svg: String, caption: String },
}

#[derive(Debug, Clone, PartialEq)]
struct Section {
    heading: Option<String>,
    blocks: Vec<Block>,
}

/// A report page, built in order: what is added goes into the last section begun (or
/// under the title, before the first).
#[derive(Debug, Clone, PartialEq)]
pub struct Page {
    title: String,
    sections: Vec<Section>,
}

const CSS: &str = "
body { font-family: 'DejaVu Sans', 'Segoe UI', Helvetica, Arial, sans-serif; color: #1b1b1b; background: #fafafa;
  margin: 0; line-height: 1.45; }
main { max-width: 1100px; margin: 0 auto; padding: 1.5rem 2rem 3rem; background: #fff; }
h1 { font-size: 1.6rem; border-bottom: 3px solid #0072b2; padding-bottom: .3rem; }
h2 { font-size: 1.25rem; margin-top: 2.2rem; border-bottom: 1px solid #ccc; padding-bottom: .2rem; }
p.note { background: #fff4d6; border-left: 4px solid #e69f00; padding: .5rem .8rem; }
.scroll { overflow-x: auto; }
table { border-collapse: collapse; margin: .8rem 0; font-size: .9rem; }
th, td { border: 1px solid #d4d4d4; padding: .25rem .55rem; text-align: left; vertical-align: top; }
thead th { background: #eef2f6; }
th[scope=row] { background: #f6f8fa; font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.strong { font-weight: 700; outline: 2px solid #1b1b1b; outline-offset: -2px; }
figure { margin: 1rem 0 1.6rem; }
figure svg { width: 100%; height: auto; display: block; border: 1px solid #e3e3e3; }
figcaption { font-size: .85rem; color: #555; margin-top: .3rem; }
footer { margin-top: 3rem; font-size: .75rem; color: #888; }
";

impl Page {
    pub fn new(title: impl Into<String>) -> Self {
        Page { title: title.into(), sections: Vec::new() }
    }

    fn push(&mut self, block: Block) -> &mut Self {
        if self.sections.is_empty() {
            self.sections.push(Section { heading: None, blocks: Vec::new() });
        }
        if let Some(section) = self.sections.last_mut() {
            section.blocks.push(block);
        }
        self
    }

    /// Begins a section under `heading`.
    pub fn section(&mut self, heading: impl Into<String>) -> &mut Self {
        self.sections.push(Section { heading: Some(heading.into()), blocks: Vec::new() });
        self
    }

    pub fn paragraph(&mut self, text: impl Into<String>) -> &mut Self {
        self.push(Block::Paragraph(text.into()))
    }

    /// A paragraph set off as a callout, for what a reader must not miss.
    pub fn note(&mut self, text: impl Into<String>) -> &mut Self {
        self.push(Block::Note(text.into()))
    }

    /// A bulleted list.
    pub fn list(&mut self, items: Vec<String>) -> &mut Self {
        self.push(Block::List(items))
    }

    /// A table of plain text cells.
    pub fn table(&mut self, header: Vec<String>, rows: Vec<Vec<String>>) -> &mut Self {
        let rows = rows.into_iter().map(|row| row.into_iter().map(Cell::new).collect()).collect();
        self.push(Block::Table { header, rows })
    }

    /// A table of styled cells.
    pub fn cell_table(&mut self, header: Vec<String>, rows: Vec<Vec<Cell>>) -> &mut Self {
        self.push(Block::Table { header, rows })
    }

    /// A matrix of numbers coloured by [`Cell::heat`] on `lo..hi`, one row per
    /// `row_labels` entry; `header` names the columns (the row-label column's heading is
    /// left empty). Rows shorter than the header are padded with empty cells.
    pub fn heat_table(
        &mut self,
        header: Vec<String>,
        row_labels: Vec<String>,
        values: Vec<Vec<f64>>,
        lo: f64,
        hi: f64,
    ) -> &mut Self {
        let columns = header.len();
        let header = std::iter::once(String::new()).chain(header).collect();
        let rows = row_labels
            .into_iter()
            .zip(values.into_iter().chain(std::iter::repeat(Vec::new())))
            .map(|(label, row)| {
                let cells = (0..columns).map(|j| match row.get(j) {
                    Some(v) => Cell::heat(*v, lo, hi, 2),
                    None => Cell::new(""),
                });
                std::iter::once(Cell::heading(label)).chain(cells).collect()
            })
            .collect();
        self.push(Block::Table { header, rows })
    }

    /// A figure: `svg` goes into the page verbatim, so it must come from
    /// [`line_plot_svg`](super::line_plot_svg) or [`bar_plot_svg`](super::bar_plot_svg) (or
    /// be as trusted); `caption` is text.
    pub fn figure(&mut self, svg: String, caption: impl Into<String>) -> &mut Self {
        self.push(Block::Figure { svg, caption: caption.into() })
    }

    pub fn to_html(&self) -> String {
        let title = escape_html(&self.title);
        let mut out = String::with_capacity(4096 + self.sections.len() * 1024);
        out.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
        out.push_str("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
        out.push_str(&format!("<title>{title}</title>\n<style>{CSS}</style>\n</head>\n<body>\n<main>\n"));
        out.push_str(&format!("<h1>{title}</h1>\n"));
        for section in &self.sections {
            out.push_str("<section>\n");
            if let Some(heading) = &section.heading {
                out.push_str(&format!("<h2>{}</h2>\n", escape_html(heading)));
            }
            for block in &section.blocks {
                block_html(block, &mut out);
            }
            out.push_str("</section>\n");
        }
        out.push_str(&format!("<footer>forgemon {}</footer>\n", env!("CARGO_PKG_VERSION")));
        out.push_str("</main>\n</body>\n</html>\n");
        out
    }

    /// Writes [`Page::to_html`] to `path`.
    pub fn write(&self, path: &Path) -> Result<(), ReportError> {
        std::fs::write(path, self.to_html()).map_err(|source| ReportError::Io {
            path: path.to_path_buf(),
            action: "write",
            source,
        })
    }
}

fn block_html(block: &Block, out: &mut String) {
    match block {
        Block::Paragraph(text) => out.push_str(&format!("<p>{}</p>\n", escape_html(text))),
        Block::Note(text) => out.push_str(&format!("<p class=\"note\">{}</p>\n", escape_html(text))),
        Block::List(items) => {
            out.push_str("<ul>\n");
            for item in items {
                out.push_str(&format!("<li>{}</li>\n", escape_html(item)));
            }
            out.push_str("</ul>\n");
        }
        Block::Table { header, rows } => {
            out.push_str("<div class=\"scroll\"><table>\n");
            if !header.is_empty() {
                out.push_str("<thead><tr>");
                for h in header {
                    out.push_str(&format!("<th scope=\"col\">{}</th>", escape_html(h)));
                }
                out.push_str("</tr></thead>\n");
            }
            out.push_str("<tbody>\n");
            for row in rows {
                out.push_str("<tr>");
                for cell in row {
                    cell.to_html(out);
                }
                out.push_str("</tr>\n");
            }
            out.push_str("</tbody>\n</table></div>\n");
        }
        Block::Figure { svg, caption } => {
            out.push_str("<figure>\n");
            out.push_str(svg);
            if !caption.is_empty() {
                out.push_str(&format!("<figcaption>{}</figcaption>\n", escape_html(caption)));
            }
            out.push_str("</figure>\n");
        }
    }
}

/// `value ± std_error` to `significant` digits, "± unknown" for a non-finite error.
pub fn format_with_error(value: f64, std_error: f64, significant: usize) -> String {
    if std_error.is_finite() {
        format!("{} ± {}", format_number(value, significant), format_number(std_error, 2))
    } else {
        format!("{} ± unknown", format_number(value, significant))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_piece_of_text_is_escaped() {
        let evil = "<script>alert('x')</script>";
        let mut page = Page::new(evil);
        page.section(evil)
            .paragraph(evil)
            .note(evil)
            .list(vec![evil.into()])
            .table(vec![evil.into()], vec![vec![evil.into()]])
            .heat_table(vec![evil.into()], vec![evil.into()], vec![vec![0.5]], -1.0, 1.0)
            .figure("<svg></svg>".into(), evil);
        let html = page.to_html();
        assert!(!html.contains("<script>"), "unescaped text in {html}");
        // title, h1, h2, paragraph, note, list item, table header and cell, heat header and
        // row label, caption
        assert_eq!(html.matches("&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt;").count(), 11);
    }

    #[test]
    fn a_heat_table_colours_cells_and_pads_short_rows() {
        let mut page = Page::new("t");
        page.heat_table(
            vec!["a".into(), "b".into()],
            vec!["a".into(), "b".into(), "c".into()],
            vec![vec![1.0, -1.0], vec![f64::NAN]],
            -1.0,
            1.0,
        );
        let html = page.to_html();
        assert!(html.contains("style=\"background:#b2182b;color:#fff\">1.00</td>"), "{html}");
        assert!(html.contains("style=\"background:#2166ac;color:#fff\">-1.00</td>"));
        assert!(html.contains("<td class=\"num\">—</td>"));
        // Row b lacks its second value and row c has none: three empty cells.
        assert_eq!(html.matches("<td></td>").count(), 3);
    }

    #[test]
    fn blocks_before_any_section_go_under_the_title() {
        let mut page = Page::new("t");
        page.paragraph("first").section("S").paragraph("second");
        let html = page.to_html();
        let first = html.find("first").unwrap();
        let heading = html.find("<h2>S</h2>").unwrap();
        assert!(first < heading && heading < html.find("second").unwrap());
    }

    #[test]
    fn a_write_error_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no-such-dir").join("report.html");
        let err = Page::new("t").write(&path).unwrap_err();
        assert!(err.to_string().contains("no-such-dir/report.html"), "{err}");
        let ok = dir.path().join("report.html");
        Page::new("t").write(&ok).unwrap();
        assert!(std::fs::read_to_string(&ok).unwrap().starts_with("<!DOCTYPE html>"));
    }

    #[test]
    fn values_carry_their_error() {
        assert_eq!(format_with_error(2.345e8, 1.2e6, 4), "2.345e8 ± 1.2e6");
        assert_eq!(format_with_error(0.5, f64::NAN, 3), "0.5 ± unknown");
    }
}
