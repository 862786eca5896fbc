//! The identification report: one HTML page that shows an engineer what `forgemon identify`
//! found and how far to trust it — the parameters with their errors and whether the data
//! determined them, how they correlate, and for every blow the measured load against the
//! fitted model's (with its Monte Carlo band), the residual and the spectra.
//!
//! It takes plain data (`IdentifyReport`) so that the fit can be tested without it and it
//! without a fit; the page is built with `crate::report`.

use std::path::Path;

use crate::report::{
    Band, BarPlot, Cell, Color, LinePlot, Page, ReportError, Series, bar_plot_svg, format_number, format_with_error,
    line_plot_svg,
};

/// Spectra are shown up to this frequency, or the data's highest if lower.
pub const SPECTRUM_MAX_HZ: f64 = 5_000.0;
/// A correlation of at least this magnitude between two parameters is highlighted: the
/// data cannot tell them apart.
pub const STRONG_CORRELATION: f64 = 0.95;

const WIDE_PX: u32 = 960;
const LOAD_PX: u32 = 380;
const RESIDUAL_PX: u32 = 240;
const SPECTRUM_PX: u32 = 340;
const ERRORS_PX: u32 = 300;

/// One identified (or fixed) parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamRow {
    /// The name with its unit, e.g. "k_N_per_m".
    pub name: String,
    pub value: f64,
    /// The absolute standard error; NaN when unknown.
    pub std_error: f64,
    pub determined: bool,
    /// Why, e.g. "correlated with m2_kg (r = 0.998)" or "fixed (sensor data sheet)".
    pub note: String,
}

/// One blow: the measured load against the fitted model's, in time and in frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct BlowFit {
    /// e.g. "blow_01.csv, v0 3.90 m/s".
    pub label: String,
    pub t_ms: Vec<f64>,
    pub measured_n: Vec<f64>,
    pub fitted_n: Vec<f64>,
    /// The Monte Carlo 95 % band of the fitted model's load at `t_ms`.
    pub band_lo_n: Option<Vec<f64>>,
    pub band_hi_n: Option<Vec<f64>>,
    pub freq_hz: Vec<f64>,
    pub measured_spectrum: Vec<f64>,
    pub fitted_spectrum: Vec<f64>,
    /// Modes found in the measured spectrum.
    pub modes_hz: Vec<f64>,
    pub rms_rel_error: f64,
    /// Used only to check the prediction, not in the fit.
    pub held_out: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct IdentifyReport {
    pub title: String,
    /// The machine kind, e.g. "drop hammer".
    pub kind: String,
    /// Plain sentences.
    pub summary: Vec<String>,
    pub params: Vec<ParamRow>,
    /// The parameters' correlation matrix, rows and columns in the order of `params`.
    pub correlations: Vec<Vec<f64>>,
    pub blows: Vec<BlowFit>,
}

/// Writes `r` as one self-contained HTML page to `path`.
pub fn write_identify_report(r: &IdentifyReport, path: &Path) -> Result<(), ReportError> {
    build_page(r)?.write(path)
}

fn build_page(r: &IdentifyReport) -> Result<Page, ReportError> {
    let mut page = Page::new(&r.title);
    page.paragraph(format!("Machine kind: {}.", r.kind));
    if !r.summary.is_empty() {
        page.list(r.summary.clone());
    }

    page.section("Parameters");
    param_table(&mut page, &r.params);

    page.section("Correlations between parameters");
    correlation_table(&mut page, r);

    if !r.blows.is_empty() {
        page.section("Fit quality per blow");
        error_overview(&mut page, &r.blows)?;
    }
    for blow in &r.blows {
        blow_section(&mut page, blow)?;
    }
    Ok(page)
}

fn param_table(page: &mut Page, params: &[ParamRow]) {
    if params.is_empty() {
        page.note("No parameters were reported.");
        return;
    }
    let undetermined = params.iter().filter(|p| !p.determined).count();
    if undetermined > 0 {
        page.note(format!(
            "{undetermined} of {} parameters are not determined by the data: their values are not to be trusted.",
            params.len()
        ));
    }
    let header = ["parameter", "value ± std error", "relative error", "status", "note"].map(String::from).to_vec();
    let rows = params
        .iter()
        .map(|p| {
            let relative = if p.std_error.is_finite() && p.value != 0.0 && p.value.is_finite() {
                format!("{} %", format_number(100.0 * p.std_error / p.value.abs(), 2))
            } else {
                "—".to_string()
            };
            let status = if p.determined {
                Cell::new("determined").on(Color::Rgb(214, 240, 222))
            } else {
                Cell::new("not determined").on(Color::Rgb(250, 214, 200)).strong()
            };
            vec![
                Cell::heading(&p.name),
                Cell::number(format_with_error(p.value, p.std_error, 4)),
                Cell::number(relative),
                status,
                Cell::new(&p.note),
            ]
        })
        .collect();
    page.cell_table(header, rows);
}

fn correlation_table(page: &mut Page, r: &IdentifyReport) {
    let n = r.params.len();
    let square = r.correlations.len() == n && r.correlations.iter().all(|row| row.len() == n);
    if n == 0 || !square {
        let rows = r.correlations.len();
        let cols = r.correlations.first().map_or(0, Vec::len);
        page.note(format!("No correlation matrix to show ({rows} × {cols} for {n} parameters)."));
        return;
    }
    page.paragraph(format!(
        "Blue is negative, red positive. Pairs with |r| ≥ {STRONG_CORRELATION} are outlined in bold: \
         the data cannot separate them."
    ));
    let header = std::iter::once(String::new()).chain(r.params.iter().map(|p| p.name.clone())).collect();
    let rows = r
        .params
        .iter()
        .zip(&r.correlations)
        .enumerate()
        .map(|(i, (p, row))| {
            let cells = row.iter().enumerate().map(|(j, &v)| {
                if i == j {
                    Cell::number("1").on(Color::Rgb(235, 235, 235))
                } else if v.abs() >= STRONG_CORRELATION {
                    Cell::heat(v, -1.0, 1.0, 3).strong()
                } else {
                    Cell::heat(v, -1.0, 1.0, 2)
                }
            });
            std::iter::once(Cell::heading(&p.name)).chain(cells).collect()
        })
        .collect();
    page.cell_table(header, rows);
}

fn role(blow: &BlowFit) -> &'static str {
    if blow.held_out { "held out (prediction check)" } else { "fitted" }
}

fn error_overview(page: &mut Page, blows: &[BlowFit]) -> Result<(), ReportError> {
    let percent = |b: &BlowFit, held_out: bool| if b.held_out == held_out { 100.0 * b.rms_rel_error } else { f64::NAN };
    let plot = BarPlot {
        title: "RMS relative error of the load, per blow".into(),
        y_label: "RMS error (%)".into(),
        groups: blows.iter().map(|b| b.label.clone()).collect(),
        bars: vec![
            ("fitted".into(), blows.iter().map(|b| percent(b, false)).collect()),
            ("held out".into(), blows.iter().map(|b| percent(b, true)).collect()),
        ],
    };
    page.figure(
        bar_plot_svg(&plot, WIDE_PX, ERRORS_PX)?,
        "Held-out blows were not used in the fit: their error is the model's prediction error.",
    );
    let rows = blows
        .iter()
        .map(|b| {
            vec![
                Cell::heading(&b.label),
                Cell::new(role(b)),
                Cell::number(format!("{} %", format_number(100.0 * b.rms_rel_error, 3))),
            ]
        })
        .collect();
    page.cell_table(vec!["blow".into(), "role".into(), "RMS relative error".into()], rows);
    Ok(())
}

fn kn(values: &[f64]) -> Vec<f64> {
    values.iter().map(|v| v / 1e3).collect()
}

fn blow_section(page: &mut Page, blow: &BlowFit) -> Result<(), ReportError> {
    if blow.held_out {
        page.section(format!("{} — held out", blow.label));
        page.note("Held out: this blow was not used in the fit; it checks the model's prediction.");
    } else {
        page.section(blow.label.clone());
    }
    page.paragraph(format!("RMS relative error of the load: {} %.", format_number(100.0 * blow.rms_rel_error, 3)));

    let band = match (&blow.band_lo_n, &blow.band_hi_n) {
        (Some(lo), Some(hi)) => Some((lo, hi)),
        _ => None,
    };

    // On a held-out blow the model is not fitted but predicts.
    let (model, title) = if blow.held_out {
        ("model prediction", format!("Load: {} (held out)", blow.label))
    } else {
        ("fitted model", format!("Load: {}", blow.label))
    };
    let mut load = LinePlot::new(title, "time (ms)", "load (kN)");
    if let Some((lo, hi)) = band {
        load.bands.push(Band {
            label: "model, Monte Carlo 95 % band".into(),
            x: blow.t_ms.clone(),
            lo: kn(lo),
            hi: kn(hi),
            color: Color::Orange,
        });
    }
    load.series.push(Series::new("measured", blow.t_ms.clone(), kn(&blow.measured_n), Color::Blue));
    load.series.push(Series::new(model, blow.t_ms.clone(), kn(&blow.fitted_n), Color::Vermillion).dashed());
    let caption = if blow.held_out {
        "Measured load and the model's prediction; this blow was not fitted."
    } else {
        "Measured load and the fitted model's."
    };
    page.figure(line_plot_svg(&load, WIDE_PX, LOAD_PX)?, caption);

    let residual_kn: Vec<f64> = blow.measured_n.iter().zip(&blow.fitted_n).map(|(m, f)| (m - f) / 1e3).collect();
    let mut residual = LinePlot::new(format!("Residual: measured − {model}"), "time (ms)", "residual (kN)");
    if let Some((lo, hi)) = band {
        // The band around the fitted curve, moved to zero: a residual inside it is within
        // the model's uncertainty.
        let around = |edge: &Vec<f64>| edge.iter().zip(&blow.fitted_n).map(|(e, f)| (e - f) / 1e3).collect();
        residual.bands.push(Band {
            label: format!("95 % band − {model}"),
            x: blow.t_ms.clone(),
            lo: around(lo),
            hi: around(hi),
            color: Color::Orange,
        });
    }
    residual.series.push(Series::new(format!("measured − {model}"), blow.t_ms.clone(), residual_kn, Color::Green));
    page.figure(
        line_plot_svg(&residual, WIDE_PX, RESIDUAL_PX)?,
        "A residual with structure is physics the model lacks.",
    );

    let nyquist_hz = blow.freq_hz.iter().copied().filter(|f| f.is_finite()).fold(0.0, f64::max);
    let max_hz = if nyquist_hz > 0.0 { nyquist_hz.min(SPECTRUM_MAX_HZ) } else { SPECTRUM_MAX_HZ };
    let shown: Vec<usize> = (0..blow.freq_hz.len()).filter(|&i| blow.freq_hz[i] <= max_hz).collect();
    let pick = |values: &[f64]| shown.iter().map(|&i| values.get(i).copied().unwrap_or(f64::NAN)).collect();
    let freq: Vec<f64> = pick(&blow.freq_hz);
    let mut spectrum = LinePlot {
        log_y: true,
        markers_x: blow.modes_hz.iter().map(|&f| (f, format!("{} Hz", format_number(f, 4)))).collect(),
        ..LinePlot::new("Load spectrum", "frequency (Hz)", "amplitude")
    };
    spectrum.series.push(Series::new("measured", freq.clone(), pick(&blow.measured_spectrum), Color::Blue));
    spectrum.series.push(Series::new(model, freq, pick(&blow.fitted_spectrum), Color::Vermillion).dashed());
    let modes: Vec<f64> = blow.modes_hz.iter().copied().filter(|f| f.is_finite()).collect();
    let modes = if modes.is_empty() {
        "No modes were found in the measured spectrum.".to_string()
    } else {
        let list: Vec<String> = modes.iter().map(|f| format!("{} Hz", format_number(*f, 4))).collect();
        format!("Grey dashed lines: modes found in the measured spectrum ({}).", list.join(", "))
    };
    page.figure(line_plot_svg(&spectrum, WIDE_PX, SPECTRUM_PX)?, modes);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic blow: a 2 ms half-sine of 800 kN with a 1.2 kHz ring on the measurement,
    /// and a spectrum with peaks at 1.2 and 3.1 kHz. Shapes only; no physics is checked.
    fn blow(label: &str, held_out: bool) -> BlowFit {
        let t_ms: Vec<f64> = (0..400).map(|i| f64::from(i) * 0.01).collect();
        let pulse = |t: f64| if t < 2.0 { 800e3 * (std::f64::consts::PI * t / 2.0).sin() } else { 0.0 };
        let fitted_n: Vec<f64> = t_ms.iter().map(|&t| pulse(t)).collect();
        let measured_n: Vec<f64> = t_ms
            .iter()
            .map(|&t| pulse(t) + 40e3 * (2.0 * std::f64::consts::PI * 1.2 * t).sin() * (-t / 1.5).exp())
            .collect();
        let freq_hz: Vec<f64> = (0..=500).map(|i| f64::from(i) * 20.0).collect();
        let peak = |f: f64, f0: f64| 1e3 / (1.0 + ((f - f0) / 40.0).powi(2));
        let floor = |f: f64| 5e4 / (1.0 + (f / 300.0).powi(2));
        let measured_spectrum: Vec<f64> =
            freq_hz.iter().map(|&f| floor(f) + peak(f, 1200.0) + peak(f, 3100.0)).collect();
        let fitted_spectrum = freq_hz.iter().map(|&f| floor(f) + peak(f, 1250.0)).collect();
        BlowFit {
            label: label.into(),
            band_lo_n: Some(fitted_n.iter().map(|f| f * 0.95 - 5e3).collect()),
            band_hi_n: Some(fitted_n.iter().map(|f| f * 1.05 + 5e3).collect()),
            t_ms,
            measured_n,
            fitted_n,
            freq_hz,
            measured_spectrum,
            fitted_spectrum,
            modes_hz: vec![1200.0, 3100.0],
            rms_rel_error: if held_out { 0.071 } else { 0.043 },
            held_out,
        }
    }

    fn sample() -> IdentifyReport {
        let param = |name: &str, value: f64, std_error: f64, determined: bool, note: &str| ParamRow {
            name: name.into(),
            value,
            std_error,
            determined,
            note: note.into(),
        };
        IdentifyReport {
            title: "Identification of hammer <H2>".into(),
            kind: "drop hammer".into(),
            summary: vec![
                "3 blows, 2 fitted and 1 held out.".into(),
                "k_N_per_m and m2_kg are strongly correlated; m2_kg is not determined.".into(),
            ],
            params: vec![
                param("k_N_per_m", 2.345e9, 1.2e7, true, ""),
                param("m2_kg", 4200.0, 3900.0, false, "correlated with k_N_per_m (r = 0.998)"),
                param("c_N_s_per_m", 1.8e5, f64::NAN, true, "fixed (sensor data sheet)"),
            ],
            correlations: vec![vec![1.0, 0.998, -0.2], vec![0.998, 1.0, 0.1], vec![-0.2, 0.1, 1.0]],
            blows: vec![blow("blow_01.csv, v0 3.90 m/s", false), blow("blow_02.csv", false), blow("blow_03.csv", true)],
        }
    }

    #[test]
    fn the_written_page_has_every_parameter_plot_and_marking() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("identify.html");
        let r = sample();
        write_identify_report(&r, &path).unwrap();
        let html = std::fs::read_to_string(&path).unwrap();

        for p in &r.params {
            assert!(html.contains(&p.name), "{} missing", p.name);
        }
        assert_eq!(html.matches(">not determined<").count(), 1);
        assert_eq!(html.matches(">determined<").count(), 2);
        assert!(html.contains("Identification of hammer &lt;H2&gt;"));
        // The error overview, then load, residual and spectrum per blow.
        let plots = 1 + 3 * r.blows.len();
        assert_eq!(html.matches("<svg").count(), plots);
        assert_eq!(html.matches("</svg>").count(), plots);
        // Every plot closes before the next opens.
        let mut rest = html.as_str();
        while let Some(open) = rest.find("<svg") {
            let close = rest[open..].find("</svg>").expect("an <svg> without </svg>");
            assert!(!rest[open + 4..open + close].contains("<svg"), "nested or unclosed <svg>");
            rest = &rest[open + close..];
        }
        // The held-out blow is marked in its heading and in the overview table.
        assert!(html.contains("<h2>blow_03.csv — held out</h2>"));
        assert_eq!(html.matches("held out (prediction check)").count(), 1);
        assert!(html.contains("Load: blow_03.csv (held out)"));
        assert_eq!(html.matches("\nmodel prediction\n</text>").count(), 2, "load and spectrum legends");
        // 0.998 is strong and outlined; the diagonal is not.
        assert_eq!(html.matches("class=\"num strong\"").count(), 2);
        // Both modes are markers on each spectrum.
        assert_eq!(html.matches("\n3100 Hz\n</text>").count(), 3);
    }

    /// The sample with a short correlation matrix and a blow whose data is cut, NaN or
    /// missing in every way the fit could hand over.
    fn ragged() -> IdentifyReport {
        let mut r = sample();
        r.correlations = vec![vec![1.0]];
        let b = &mut r.blows[0];
        b.measured_n.truncate(10);
        b.fitted_n[5] = f64::NAN;
        b.band_hi_n = None;
        b.freq_hz.clear();
        b.measured_spectrum = vec![0.0; 3];
        b.modes_hz = vec![f64::NAN];
        r.blows[1].t_ms.clear();
        r
    }

    #[test]
    fn ragged_and_missing_data_still_make_a_page() {
        let r = ragged();
        let html = build_page(&r).unwrap().to_html();
        assert!(html.contains("No correlation matrix to show (1 × 1 for 3 parameters)"));
        assert!(html.contains("no data to plot"));
        assert!(!html.contains("NaN"));
        assert_eq!(html.matches("<svg").count(), 1 + 3 * r.blows.len());
    }

    /// Writes the sample pages to /tmp/identify-sample.html and /tmp/identify-ragged.html
    /// for a person to look at: `cargo test --release --lib identify::report -- --ignored`.
    #[test]
    #[ignore = "writes sample pages to /tmp for a person to look at"]
    fn render_the_samples_for_a_person() {
        write_identify_report(&sample(), Path::new("/tmp/identify-sample.html")).unwrap();
        write_identify_report(&ragged(), Path::new("/tmp/identify-ragged.html")).unwrap();
    }
}
