//! Capture CSV files (docs/interfaces.md §1): `t_s,load_N,disp_m,acc_mps2` in any column order,
//! extra columns ignored, constant sample period. The reader streams any `BufRead` into
//! `SampleBatch`es (a 10-minute capture at 100 kHz is gigabytes), and every error names the
//! file, the line and the column. It opens no file itself.

use std::io::{BufRead, Write};

use super::sample::{Role, SampleBatch};

/// Sample-period jitter allowed by docs/interfaces.md §1: each time stamp within 1 % of a period
/// of the uniform grid. A step spans two stamps, so it may differ from the period by twice
/// that (`MAX_STEP_DEVIATION`).
pub const MAX_PERIOD_JITTER: f64 = 0.01;
/// How far one step may differ from the period: its two stamps' jitter. The period itself is
/// the mean of the `n` steps before, whose ends carry the same jitter, so a step is compared
/// with it within `MAX_STEP_DEVIATION * (1 + 1/n)`.
pub const MAX_STEP_DEVIATION: f64 = 2.0 * MAX_PERIOD_JITTER;
/// Default length of the batches the reader emits, s (DESIGN.md §3: 10–100 ms per message).
pub const DEFAULT_BATCH_S: f64 = 0.05;

/// What is wrong with a capture. Every variant names the file; most name the line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CaptureError {
    #[error("{origin}: empty file (no header line)")]
    Empty { origin: String },
    #[error("{origin}:1: header lacks column '{column}' (it needs t_s and at least two of load_N, disp_m, acc_mps2)")]
    MissingColumn { origin: String, column: &'static str },
    #[error("{origin}: no samples after the header")]
    NoSamples { origin: String },
    #[error("{origin}:{line}: has {found} fields, the header has {expected}")]
    FieldCount { origin: String, line: usize, found: usize, expected: usize },
    #[error("{origin}:{line}: column '{column}': '{text}' is not a finite number")]
    NotANumber { origin: String, line: usize, column: String, text: String },
    #[error("{origin}:{line}: t_s = {t_s} does not increase (previous {previous})")]
    NotIncreasing { origin: String, line: usize, t_s: f64, previous: f64 },
    #[error(
        "{origin}:{line}: sample period {period_s:e} s differs from the mean step so far, {expected_s:e} s, by more \
         than the time stamps' 1 % jitter allows"
    )]
    Jitter { origin: String, line: usize, period_s: f64, expected_s: f64 },
    #[error("{origin}:{line}: cannot read: {message}")]
    Read { origin: String, line: usize, message: String },
}

/// Streams a capture into batches of about `batch_s` seconds.
pub struct CaptureReader<R> {
    origin: String,
    lines: std::io::Lines<R>,
    line_no: usize,
    /// Column index of t_s, load_N, disp_m, acc_mps2; `None` for a channel the capture lacks
    /// (a machine without that sensor, issue 43).
    cols: [Option<usize>; 4],
    n_fields: usize,
    batch_len: Option<usize>,
    batch_s: f64,
    period_s: Option<f64>,
    first_t: Option<f64>,
    last_t: Option<f64>,
    seq: u64,
    pending: Option<[f64; 4]>,
    done: bool,
    samples: u64,
}

impl<R: BufRead> CaptureReader<R> {
    /// Read the header of `reader`; `origin` names the file in errors.
    pub fn new(origin: impl Into<String>, reader: R, batch_s: f64) -> Result<Self, CaptureError> {
        let origin = origin.into();
        let mut lines = reader.lines();
        let header = match lines.next() {
            None => return Err(CaptureError::Empty { origin }),
            Some(Err(e)) => return Err(CaptureError::Read { origin, line: 1, message: e.to_string() }),
            Some(Ok(h)) => h,
        };
        let names: Vec<&str> = header.trim_end_matches('\r').split(',').map(str::trim).collect();
        let columns = ["t_s", "load_N", "disp_m", "acc_mps2"];
        let cols = columns.map(|column| names.iter().position(|n| *n == column));
        // The time, and two of the three channels at least: one may be missing.
        let missing = |k: usize| CaptureError::MissingColumn { origin: origin.clone(), column: columns[k] };
        if cols[0].is_none() {
            return Err(missing(0));
        }
        if cols[1..].iter().filter(|c| c.is_none()).count() > 1 {
            let first = (1..4).find(|&k| cols[k].is_none()).unwrap_or(1);
            return Err(missing(first));
        }
        Ok(CaptureReader {
            n_fields: names.len(),
            origin,
            lines,
            line_no: 1,
            cols,
            batch_len: None,
            batch_s,
            period_s: None,
            first_t: None,
            last_t: None,
            seq: 0,
            pending: None,
            done: false,
            samples: 0,
        })
    }

    /// Samples read so far.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// The sample period, once two samples have been read.
    pub fn period_s(&self) -> Option<f64> {
        self.period_s
    }

    fn next_row(&mut self) -> Result<Option<[f64; 4]>, CaptureError> {
        loop {
            let Some(line) = self.lines.next() else { return Ok(None) };
            self.line_no += 1;
            let line = line.map_err(|e| CaptureError::Read {
                origin: self.origin.clone(),
                line: self.line_no,
                message: e.to_string(),
            })?;
            let line = line.trim_end_matches('\r');
            if line.trim().is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split(',').collect();
            if fields.len() != self.n_fields {
                return Err(CaptureError::FieldCount {
                    origin: self.origin.clone(),
                    line: self.line_no,
                    found: fields.len(),
                    expected: self.n_fields,
                });
            }
            let mut row = [f64::NAN; 4];
            for (k, (&c, name)) in self.cols.iter().zip(["t_s", "load_N", "disp_m", "acc_mps2"]).enumerate() {
                let Some(c) = c else { continue };
                let text = fields[c].trim();
                row[k] =
                    text.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| CaptureError::NotANumber {
                        origin: self.origin.clone(),
                        line: self.line_no,
                        column: name.to_string(),
                        text: text.to_string(),
                    })?;
            }
            let t = row[0];
            if let Some(prev) = self.last_t {
                if t <= prev {
                    return Err(CaptureError::NotIncreasing {
                        origin: self.origin.clone(),
                        line: self.line_no,
                        t_s: t,
                        previous: prev,
                    });
                }
                let dt = t - prev;
                // The period is the mean step so far; each stamp may sit 1 % of it off the
                // grid (docs/interfaces.md §1), so a step may differ by 2 %, and the mean by its
                // own ends' jitter over the steps it spans. That also covers the
                // rounding of the printed times (7 decimals at 100 kHz, as in the contract's
                // example, is ±0.5 % a stamp).
                let (mean, steps) = match self.first_t {
                    Some(t0) if self.samples > 1 => {
                        ((prev - t0) / (self.samples - 1) as f64, (self.samples - 1) as f64)
                    }
                    _ => (dt, 1.0),
                };
                if (dt - mean).abs() > MAX_STEP_DEVIATION * (1.0 + 1.0 / steps) * mean * (1.0 + 1e-9) {
                    return Err(CaptureError::Jitter {
                        origin: self.origin.clone(),
                        line: self.line_no,
                        period_s: dt,
                        expected_s: mean,
                    });
                }
                self.period_s = Some((t - self.first_t.unwrap_or(prev)) / self.samples as f64);
            } else {
                self.first_t = Some(t);
            }
            self.last_t = Some(t);
            self.samples += 1;
            return Ok(Some(row));
        }
    }

    /// The next batch, or `None` at the end.
    pub fn next_batch(&mut self) -> Result<Option<SampleBatch>, CaptureError> {
        if self.done {
            return Ok(None);
        }
        let mut rows: Vec<[f64; 4]> = Vec::new();
        if let Some(r) = self.pending.take() {
            rows.push(r);
        }
        loop {
            let target = self.batch_len.unwrap_or(usize::MAX);
            if rows.len() >= target {
                break;
            }
            match self.next_row()? {
                None => {
                    self.done = true;
                    break;
                }
                Some(r) => {
                    rows.push(r);
                    if self.batch_len.is_none()
                        && let Some(p) = self.period_s
                    {
                        self.batch_len = Some(((self.batch_s / p).round() as usize).max(1));
                    }
                }
            }
        }
        if rows.is_empty() {
            return if self.samples == 0 {
                Err(CaptureError::NoSamples { origin: self.origin.clone() })
            } else {
                Ok(None)
            };
        }
        // The period of a one-sample file is unknown; 1 s keeps the batch well-formed.
        let period_s = self.period_s.unwrap_or(1.0);
        let t0_ns = (rows[0][0] * 1e9).round() as i64;
        let present: Vec<usize> = (1..4).filter(|&k| self.cols[k].is_some()).collect();
        let mut values = Vec::with_capacity(rows.len() * present.len());
        for r in &rows {
            values.extend(present.iter().map(|&k| r[k]));
        }
        let batch = SampleBatch {
            source: self.origin.clone(),
            seq: self.seq,
            device_time_ns: t0_ns,
            host_time_ns: t0_ns,
            period_ns: period_s * 1e9,
            roles: present.iter().map(|&k| [Role::Load, Role::Disp, Role::Acc][k - 1]).collect(),
            values,
        };
        self.seq += 1;
        Ok(Some(batch))
    }

    /// Read everything into batches.
    pub fn read_all(mut self) -> Result<Vec<SampleBatch>, CaptureError> {
        let mut out = Vec::new();
        while let Some(b) = self.next_batch()? {
            out.push(b);
        }
        Ok(out)
    }
}

/// One sample of a capture, in docs/interfaces.md §1 units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureRow {
    pub t_s: f64,
    pub load_n: f64,
    pub disp_m: f64,
    pub acc_mps2: f64,
}

/// Write rows as a capture CSV.
pub fn write_capture(w: &mut impl Write, rows: &[CaptureRow]) -> std::io::Result<()> {
    writeln!(w, "t_s,load_N,disp_m,acc_mps2")?;
    for r in rows {
        writeln!(w, "{:.9},{:.1},{:.6},{:.4}", r.t_s, r.load_n, r.disp_m, r.acc_mps2)?;
    }
    Ok(())
}

/// The file names of a capture directory's blows, `blow_01.csv`, `blow_02.csv`, ... in blow
/// order (by the number, so `blow_10` follows `blow_9`). Other files are ignored.
pub fn blow_files(names: impl IntoIterator<Item = String>) -> Vec<String> {
    let mut numbered: Vec<(u64, String)> = names
        .into_iter()
        .filter_map(|n| {
            let num = n.strip_prefix("blow_")?.strip_suffix(".csv")?.parse().ok()?;
            Some((num, n))
        })
        .collect();
    numbered.sort();
    numbered.into_iter().map(|(_, n)| n).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<Vec<SampleBatch>, CaptureError> {
        CaptureReader::new("c.csv", text.as_bytes(), 0.002)?.read_all()
    }

    #[test]
    fn columns_in_any_order_with_extras() {
        let text =
            "acc_mps2,extra,t_s,disp_m,load_N\n9.8,x,10.000,0.5,100\n9.7,y,10.001,0.6,200\n9.6,z,10.002,0.7,300\n";
        let b = read(text).unwrap();
        assert_eq!(b.len(), 2, "2 ms batches at 1 kHz");
        assert_eq!(b[0].roles, vec![Role::Load, Role::Disp, Role::Acc]);
        assert_eq!(b[0].values, vec![100.0, 0.5, 9.8, 200.0, 0.6, 9.7]);
        assert_eq!(b[1].values, vec![300.0, 0.7, 9.6]);
        assert_eq!(b[0].device_time_ns, 10_000_000_000);
        assert!((b[0].period_ns - 1e6).abs() < 1e-3);
        assert_eq!((b[0].seq, b[1].seq), (0, 1));
    }

    /// Issue 43: a capture may lack one channel (a hammer without a load cell); its batches
    /// then carry the other two, in any column order.
    #[test]
    fn a_capture_without_one_channel_gives_batches_of_the_other_two() {
        let b = read("acc_mps2,t_s,disp_m\n9.8,10.000,0.5\n9.7,10.001,0.6\n").unwrap();
        assert_eq!(b[0].roles, vec![Role::Disp, Role::Acc]);
        assert_eq!(b[0].values, vec![0.5, 9.8, 0.6, 9.7]);
        let b = read("t_s,load_N,acc_mps2\n0,100,9.8\n0.001,200,9.7\n").unwrap();
        assert_eq!(b[0].roles, vec![Role::Load, Role::Acc]);
        assert_eq!(b[0].values, vec![100.0, 9.8, 200.0, 9.7]);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let e = read("").unwrap_err();
        assert_eq!(e.to_string(), "c.csv: empty file (no header line)");
        let e = read("t_s,load_N\n1,2\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.csv:1: header lacks column 'disp_m' (it needs t_s and at least two of load_N, disp_m, acc_mps2)"
        );
        let e = read("load_N,disp_m,acc_mps2\n1,2,3\n").unwrap_err();
        assert!(e.to_string().starts_with("c.csv:1: header lacks column 't_s'"), "{e}");
        let e = read("t_s,load_N,disp_m,acc_mps2\n").unwrap_err();
        assert_eq!(e.to_string(), "c.csv: no samples after the header");
        let e = read("t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,abc,2,3\n").unwrap_err();
        assert_eq!(e.to_string(), "c.csv:3: column 'load_N': 'abc' is not a finite number");
        let e = read("t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,1,2,3\n0.0005,1,2,3\n").unwrap_err();
        assert!(e.to_string().starts_with("c.csv:4: t_s = 0.0005 does not increase"), "{e}");
        let e = read("t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,1,2,3\n0.0025,1,2,3\n").unwrap_err();
        assert!(e.to_string().starts_with("c.csv:4: sample period"), "{e}");
        let e = read("t_s,load_N,disp_m,acc_mps2\n0,1,2,3\n0.001,1,2\n").unwrap_err();
        assert_eq!(e.to_string(), "c.csv:3: has 3 fields, the header has 4");
        let e = read("t_s,load_N,disp_m,acc_mps2\n0,1,2,NaN\n").unwrap_err();
        assert!(e.to_string().contains("'NaN' is not a finite number"), "{e}");
    }

    #[test]
    fn timestamps_rounded_to_the_contract_example_resolution_are_accepted() {
        // docs/interfaces.md §1 prints t_s with 7 decimals; at 100 kHz a step is 10 µs ± 0.1 µs.
        let mut text = String::from("t_s,load_N,disp_m,acc_mps2\n");
        for i in 0..1000 {
            text.push_str(&format!("{:.7},0,0,0\n", 79.9620978 + i as f64 * 1e-5));
        }
        let b = read(&text).unwrap();
        assert!((b[0].period_ns - 1e4).abs() < 1.0, "{}", b[0].period_ns);
        // 3 kHz with 4 decimals is 10 % jitter: refused.
        let mut text = String::from("t_s,load_N,disp_m,acc_mps2\n");
        for i in 0..100 {
            text.push_str(&format!("{:.4},0,0,0\n", i as f64 / 3000.0));
        }
        assert!(matches!(read(&text), Err(CaptureError::Jitter { .. })));
    }

    /// Stamps off the grid by up to 0.95 % of a period either way (a DAQ's jitter within
    /// docs/interfaces.md §1's 1 %), in the worst order: a step 1.9 % long right after one 1.9 %
    /// short. Accepted, on the grid's period; a stamp 2.5 % off is refused.
    #[test]
    fn stamps_jittered_within_the_contract_are_accepted() {
        let offsets = [0.0095, -0.0095, 0.0095, -0.0095, 0.0, 0.0095, -0.0095];
        let text = |last: f64| {
            let mut text = String::from("t_s,load_N,disp_m,acc_mps2\n");
            for i in 0..200 {
                let off = if i == 150 { last } else { offsets[i % offsets.len()] };
                text.push_str(&format!("{:.10},0,0,0\n", 3.0 + (i as f64 + off) * 1e-4));
            }
            text
        };
        let b = read(&text(0.0)).unwrap();
        assert!((b[0].period_ns - 1e5).abs() < 100.0, "{}", b[0].period_ns);
        let e = read(&text(0.035)).unwrap_err();
        assert!(e.to_string().starts_with("c.csv:152: sample period"), "{e}");
    }

    #[test]
    fn blow_files_sort_by_number() {
        let names = ["blow_10.csv", "blow_2.csv", "process.toml", "blow_01.csv", "notes.txt"].map(String::from);
        assert_eq!(blow_files(names), vec!["blow_01.csv", "blow_2.csv", "blow_10.csv"]);
    }

    #[test]
    fn written_rows_read_back() {
        let rows: Vec<CaptureRow> = (0..10)
            .map(|i| CaptureRow { t_s: 5.0 + i as f64 * 1e-5, load_n: i as f64, disp_m: 0.1, acc_mps2: 9.81 })
            .collect();
        let mut buf = Vec::new();
        write_capture(&mut buf, &rows).unwrap();
        let b = CaptureReader::new("w.csv", buf.as_slice(), 1.0).unwrap().read_all().unwrap();
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].len(), 10);
        assert_eq!(b[0].values[27], 9.0);
    }
}
