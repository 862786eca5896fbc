//! A small kit for self-contained HTML reports: line and bar plots rendered to inline SVG
//! (`plot`), and a page of sections, paragraphs, tables and figures rendered to one HTML
//! file with inline CSS and no JavaScript or external assets (`page`). `identify` and
//! `diagnose` write their reports with it; it knows nothing about forging.
//!
//! Everything here is presentation: no physics, no clock. The only IO is
//! [`Page::write`], which names the file in its error.

mod page;
mod plot;

use std::path::PathBuf;

pub use page::{Cell, Page, format_with_error};
pub use plot::{Band, BarPlot, LinePlot, Series, bar_plot_svg, line_plot_svg};

/// An error building or writing a report.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("{path}: cannot {action}: {source}", path = path.display())]
    Io {
        path: PathBuf,
        /// What was being done: "write", ...
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// plotters failed to draw `what`; its error type is generic over the backend, so it is
    /// kept as text.
    #[error("cannot draw the plot {what:?}: {reason}")]
    Plot { what: String, reason: String },
    #[error("the embedded font assets/DejaVuSans.ttf is not a valid TrueType font")]
    Font,
}

/// A colour of the report's palette. The named ones are the Okabe–Ito palette, which stays
/// distinguishable for the common forms of colour blindness and in greyscale print.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Color {
    Blue,
    Orange,
    Green,
    Vermillion,
    Sky,
    Purple,
    Yellow,
    Black,
    Grey,
    Rgb(u8, u8, u8),
}

impl Color {
    /// The named colours in the order series should take them.
    pub const PALETTE: [Color; 7] =
        [Color::Blue, Color::Orange, Color::Green, Color::Vermillion, Color::Purple, Color::Sky, Color::Yellow];

    /// The `i`-th colour of [`Color::PALETTE`], cycling.
    pub fn nth(i: usize) -> Color {
        Self::PALETTE[i % Self::PALETTE.len()]
    }

    pub fn rgb(self) -> (u8, u8, u8) {
        match self {
            Color::Blue => (0, 114, 178),
            Color::Orange => (230, 159, 0),
            Color::Green => (0, 158, 115),
            Color::Vermillion => (213, 94, 0),
            Color::Sky => (86, 180, 233),
            Color::Purple => (204, 121, 167),
            Color::Yellow => (240, 228, 66),
            Color::Black => (0, 0, 0),
            Color::Grey => (120, 120, 120),
            Color::Rgb(r, g, b) => (r, g, b),
        }
    }

    /// `#rrggbb`, for CSS.
    pub fn hex(self) -> String {
        let (r, g, b) = self.rgb();
        format!("#{r:02x}{g:02x}{b:02x}")
    }

    /// Whether black text on this colour is easier to read than white (WCAG relative
    /// luminance above the black/white crossover of about 0.18).
    pub fn is_light(self) -> bool {
        let lin = |c: u8| {
            let c = f64::from(c) / 255.0;
            if c <= 0.040_45 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
        };
        let (r, g, b) = self.rgb();
        0.2126 * lin(r) + 0.7152 * lin(g) + 0.0722 * lin(b) > 0.18
    }

    /// The colour of `value` on a diverging blue–white–red scale from `lo` (blue) through
    /// the midpoint (white) to `hi` (red), clamped at the ends; `None` for a non-finite
    /// value or an empty scale. The end colours are ColorBrewer's RdBu.
    pub fn diverging(value: f64, lo: f64, hi: f64) -> Option<Color> {
        if !value.is_finite() || !lo.is_finite() || !hi.is_finite() || hi <= lo {
            return None;
        }
        const BLUE: (f64, f64, f64) = (33.0, 102.0, 172.0);
        const WHITE: (f64, f64, f64) = (247.0, 247.0, 247.0);
        const RED: (f64, f64, f64) = (178.0, 24.0, 43.0);
        let t = ((value - lo) / (hi - lo)).clamp(0.0, 1.0);
        let (from, to, s) = if t < 0.5 { (BLUE, WHITE, t * 2.0) } else { (WHITE, RED, t * 2.0 - 1.0) };
        let mix = |a: f64, b: f64| (a + (b - a) * s).round() as u8;
        Some(Color::Rgb(mix(from.0, to.0), mix(from.1, to.1), mix(from.2, to.2)))
    }
}

/// `value` with `significant` significant digits, trailing zeros dropped, in scientific
/// notation (`2.35e8`) outside 1e-3..1e5; "NaN", "inf" and "-inf" as such.
pub fn format_number(value: f64, significant: usize) -> String {
    if value.is_nan() {
        return "NaN".into();
    }
    if value.is_infinite() {
        return if value > 0.0 { "inf".into() } else { "-inf".into() };
    }
    if value == 0.0 {
        return "0".into();
    }
    let significant = significant.max(1);
    let magnitude = value.abs().log10().floor() as i32;
    if !(-3..5).contains(&magnitude) {
        let text = format!("{:.*e}", significant - 1, value);
        let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
        return format!("{}e{exponent}", trim_zeros(mantissa));
    }
    let decimals = (significant as i32 - 1 - magnitude).max(0) as usize;
    trim_zeros(&format!("{value:.decimals$}")).to_string()
}

fn trim_zeros(text: &str) -> &str {
    if text.contains('.') { text.trim_end_matches('0').trim_end_matches('.') } else { text }
}

/// `text` with the five characters that matter in HTML text and attribute values escaped.
pub fn escape_html(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_keep_their_significant_digits_and_drop_trailing_zeros() {
        assert_eq!(format_number(0.1 + 0.2, 4), "0.3");
        assert_eq!(format_number(1500.0, 4), "1500");
        assert_eq!(format_number(4.56789, 3), "4.57");
        assert_eq!(format_number(-0.012345, 3), "-0.0123");
        assert_eq!(format_number(2.345e8, 4), "2.345e8");
        assert_eq!(format_number(2.5e-5, 3), "2.5e-5");
        assert_eq!(format_number(f64::NAN, 3), "NaN");
        assert_eq!(format_number(0.0, 3), "0");
    }

    #[test]
    fn html_escaping_covers_markup_and_quotes() {
        assert_eq!(escape_html(r#"<a href="x">'&'</a>"#), "&lt;a href=&quot;x&quot;&gt;&#39;&amp;&#39;&lt;/a&gt;");
    }

    #[test]
    fn the_diverging_scale_runs_blue_white_red_and_clamps() {
        assert_eq!(Color::diverging(-1.0, -1.0, 1.0), Some(Color::Rgb(33, 102, 172)));
        assert_eq!(Color::diverging(0.0, -1.0, 1.0), Some(Color::Rgb(247, 247, 247)));
        assert_eq!(Color::diverging(5.0, -1.0, 1.0), Some(Color::Rgb(178, 24, 43)));
        assert_eq!(Color::diverging(f64::NAN, -1.0, 1.0), None);
        assert_eq!(Color::diverging(0.0, 1.0, 1.0), None);
        assert!(!Color::diverging(1.0, -1.0, 1.0).is_some_and(Color::is_light));
        assert!(Color::diverging(0.1, -1.0, 1.0).is_some_and(Color::is_light));
    }
}
