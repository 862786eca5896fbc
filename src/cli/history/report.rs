//! `forgemon history report --db DB --recipe PART.recipe.toml --shift START [--hours 8] -o
//! OUT.html`: a shift's quality report from the history (issue 44): the shift's blows,
//! billets, NOK blows, lots and die sets; SPC per blow of the recipe (`history::spc`); the
//! individuals and moving-range charts of each blow's efficiency; and each lot's and die
//! set's billets. One self-contained HTML file (`report::Page`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use serde_json::{Map, Value};

use super::{FilterArgs, existing, parse_time};
use crate::history::query::{Filter, Table, open_read, rows};
use crate::history::spc::{Capability, capability};
use crate::report::{Color, LinePlot, Page, Series, line_plot_svg};

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The history database.
    #[arg(long, value_name = "DB")]
    pub db: PathBuf,
    /// The recipe file: its name selects the blows, its windows are the limits.
    #[arg(long, value_name = "PART.recipe.toml")]
    pub recipe: PathBuf,
    /// The shift's start: RFC 3339 or a UTC date.
    #[arg(long, value_name = "START")]
    pub shift: String,
    /// The shift's length, h.
    #[arg(long, default_value_t = 8.0)]
    pub hours: f64,
    #[command(flatten)]
    pub filter: FilterArgs,
    /// Where to write the report.
    #[arg(short, long, value_name = "OUT.html")]
    pub out: PathBuf,
}

type Row = Map<String, Value>;

fn num(r: &Row, k: &str) -> Option<f64> {
    r.get(k).and_then(Value::as_f64)
}

fn text<'a>(r: &'a Row, k: &str) -> &'a str {
    r.get(k).and_then(Value::as_str).unwrap_or("-")
}

pub fn run(a: ReportArgs) -> anyhow::Result<ExitCode> {
    existing(&a.db)?;
    if !(a.hours > 0.0 && a.hours <= 24.0 * 31.0) {
        anyhow::bail!("--hours {}: a shift is over 0 and at most 744 h", a.hours);
    }
    let recipe =
        crate::config::recipe::parse_recipe(&a.recipe.display().to_string(), &crate::cli::read_text(&a.recipe)?)?;
    let start = parse_time("--shift", &a.shift)?;
    let end = start + (a.hours * 3.6e12) as i64;
    let base = Filter { since_ns: Some(start), until_ns: Some(end), ..a.filter.filter()? };
    let conn = open_read(&a.db)?;
    let blows = rows(&conn, &a.db, Table::Blows, &Filter { recipe: Some(recipe.name.clone()), ..base.clone() })?;
    let billets = rows(&conn, &a.db, Table::Billets, &Filter { recipe: Some(recipe.name.clone()), ..base })?;
    let when = |ns: i64| chrono::DateTime::from_timestamp_nanos(ns).format("%Y-%m-%d %H:%M UTC").to_string();
    let mut page = Page::new(format!("Shift report: {}, {} to {}", recipe.name, when(start), when(end)));
    summary(&mut page, &blows, &billets);
    spc_table(&mut page, &recipe, &blows);
    charts(&mut page, &recipe, &blows)?;
    groups(&mut page, &billets);
    page.write(&a.out)?;
    eprintln!("forgemon: {}: {} blows, {} billets", a.out.display(), blows.len(), billets.len());
    Ok(ExitCode::SUCCESS)
}

fn summary(page: &mut Page, blows: &[Row], billets: &[Row]) {
    let nok = blows.iter().filter(|b| text(b, "judgement") == "NOK").count();
    let distinct = |k: &str| {
        let mut v: Vec<&str> = billets.iter().map(|b| text(b, k)).collect();
        v.sort_unstable();
        v.dedup();
        v.join(", ")
    };
    page.section("The shift");
    page.table(
        vec!["blows".into(), "NOK blows".into(), "billets".into(), "lots".into(), "die sets".into()],
        vec![vec![
            blows.len().to_string(),
            nok.to_string(),
            billets.len().to_string(),
            distinct("lot"),
            distinct("die_set"),
        ]],
    );
}

/// The values of `column` on blow `blow` of the recipe, in time order.
fn values(blows: &[Row], blow: u32, column: &str) -> Vec<f64> {
    blows.iter().filter(|b| num(b, "billet_blow") == Some(f64::from(blow))).filter_map(|b| num(b, column)).collect()
}

fn spc_table(page: &mut Page, recipe: &crate::recipe::Recipe, blows: &[Row]) {
    let f = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.2}"));
    let mut table = Vec::new();
    for w in &recipe.blows {
        for (column, win) in [("efficiency", w.efficiency), ("plastic_J", w.plastic_j), ("peak_load_N", w.peak_load_n)]
        {
            let Some(c) = capability(&values(blows, w.blow, column), win.min, win.max) else { continue };
            table.push(vec![
                w.blow.to_string(),
                column.to_string(),
                c.n.to_string(),
                format!("{:.4}", c.mean),
                format!("{:.4}", c.sd),
                format!("{:.4} – {:.4}", c.lsl, c.usl),
                f(c.cp),
                f(c.cpk),
                c.out_of_control.len().to_string(),
            ]);
        }
    }
    page.section("Capability per blow");
    page.paragraph("Cp and Cpk against the recipe's windows, with the spread from the moving range (MR̄/1.128).");
    let header = ["blow", "quantity", "n", "mean", "sd", "window", "Cp", "Cpk", "out of control"];
    page.table(header.iter().map(|h| h.to_string()).collect(), table);
}

fn charts(page: &mut Page, recipe: &crate::recipe::Recipe, blows: &[Row]) -> anyhow::Result<()> {
    page.section("Individuals and moving-range charts: efficiency");
    for w in &recipe.blows {
        let xs = values(blows, w.blow, "efficiency");
        let Some(c) = capability(&xs, w.efficiency.min, w.efficiency.max) else { continue };
        page.figure(line_plot_svg(&individuals(w.blow, &xs, &c), 900, 220)?, format!("blow {}: individuals", w.blow));
        page.figure(line_plot_svg(&moving_range(w.blow, &xs, &c), 900, 160)?, format!("blow {}: moving range", w.blow));
    }
    Ok(())
}

fn flat(label: &str, n: usize, y: f64, color: Color) -> Series {
    Series::new(label, vec![1.0, n as f64], vec![y, y], color).dashed()
}

fn individuals(blow: u32, xs: &[f64], c: &Capability) -> LinePlot {
    let n = xs.len();
    let mut p = LinePlot::new(format!("blow {blow}: efficiency"), "billet in the shift", "efficiency");
    p.series = vec![
        Series::new("efficiency", (1..=n).map(|i| i as f64).collect(), xs.to_vec(), Color::Blue),
        flat("mean", n, c.mean, Color::Black),
        flat("UCL", n, c.x_ucl, Color::Vermillion),
        flat("LCL", n, c.x_lcl, Color::Vermillion),
        flat("USL (recipe)", n, c.usl, Color::Green),
        flat("LSL (recipe)", n, c.lsl, Color::Green),
    ];
    p
}

fn moving_range(blow: u32, xs: &[f64], c: &Capability) -> LinePlot {
    let mr: Vec<f64> = xs.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let n = xs.len();
    let mut p = LinePlot::new(format!("blow {blow}: moving range"), "billet in the shift", "moving range");
    p.series = vec![
        Series::new("moving range", (2..=n).map(|i| i as f64).collect(), mr, Color::Orange),
        flat("MR̄", n, c.mr_bar, Color::Black),
        flat("upper limit", n, c.mr_ucl, Color::Vermillion),
    ];
    p
}

/// Each lot's and die set's billets: count and mean efficiency.
fn groups(page: &mut Page, billets: &[Row]) {
    for (key, title) in [("lot", "Lots"), ("die_set", "Die sets")] {
        let mut by: std::collections::BTreeMap<&str, (usize, f64, usize)> = std::collections::BTreeMap::new();
        for b in billets {
            let e = by.entry(text(b, key)).or_default();
            e.0 += 1;
            if let Some(x) = num(b, "efficiency") {
                e.1 += x;
                e.2 += 1;
            }
        }
        let table = by
            .into_iter()
            .map(|(k, (n, sum, m))| {
                let mean = if m > 0 { format!("{:.4}", sum / m as f64) } else { "-".into() };
                vec![k.to_string(), n.to_string(), mean]
            })
            .collect();
        page.section(title);
        page.table(vec![key.into(), "billets".into(), "mean efficiency".into()], table);
    }
}
