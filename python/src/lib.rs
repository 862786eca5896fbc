//! `forgemon._forgemon`: the library's verbs for Python (issue 45). Each function runs the
//! same code as the CLI verb of its name, given the same arguments (it parses them with the
//! verb's own clap definition), with the GIL released; tables cross as Arrow IPC streams
//! (`forgemon/__init__.py` makes DataFrames of them with pyarrow, no per-row Python loop).
//! An error becomes `forgemon.ForgemonError` (a `ValueError`) with `file`, `line` and `key`
//! set when the error names them.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, Schema};
use forgemon::config::{ConfigError, parse_machine, parse_process_sheet};
use forgemon::record::{Payload, RecordReader};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use serde_json::Value;

create_exception!(_forgemon, ForgemonError, pyo3::exceptions::PyValueError);

/// `e` as a `ForgemonError`, with the file, line and key of a configuration error in its
/// chain; else `file` is `path` when given.
fn error(e: anyhow::Error, path: Option<&Path>) -> PyErr {
    let config = e.chain().find_map(|c| c.downcast_ref::<ConfigError>());
    let (file, line, key) = match config {
        Some(c) => {
            let place = match c {
                ConfigError::Syntax { place, .. }
                | ConfigError::UnknownKey { place, .. }
                | ConfigError::Missing { place, .. }
                | ConfigError::Invalid { place, .. }
                | ConfigError::TooLarge { place, .. } => place,
            };
            (Some(place.origin.clone()), place.at.map(|p| p.line), c.key().map(str::to_string))
        }
        None => (path.map(|p| p.display().to_string()), None, None),
    };
    let err = ForgemonError::new_err(format!("{e:#}"));
    Python::attach(|py| {
        let v = err.value(py);
        // Setting attributes on a fresh exception object cannot fail but by memory.
        let _ = v.setattr("file", file);
        let _ = v.setattr("line", line);
        let _ = v.setattr("key", key);
    });
    err
}

/// A verb's arguments from `argv`, parsed by its clap definition as the CLI parses them.
fn verb_args<A: clap::Args + clap::FromArgMatches>(verb: &str, argv: &[String]) -> PyResult<A> {
    let cmd = A::augment_args(clap::Command::new(verb.to_string()).no_binary_name(true));
    let matches = cmd.try_get_matches_from(argv).map_err(|e| ForgemonError::new_err(e.render().to_string()))?;
    A::from_arg_matches(&matches).map_err(|e| ForgemonError::new_err(e.to_string()))
}

/// A batch as an Arrow IPC stream.
fn ipc(batch: &RecordBatch) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut w = arrow_ipc::writer::StreamWriter::try_new(&mut out, &batch.schema())?;
    w.write(batch)?;
    w.finish()?;
    drop(w);
    Ok(out)
}

/// JSON objects (one level of nested objects flattened to `outer.inner`) as a batch, the
/// schema inferred from them.
fn json_batch(rows: &[Value]) -> anyhow::Result<RecordBatch> {
    let flat: Vec<Value> = rows.iter().map(flatten).collect();
    let schema = arrow_json::reader::infer_json_schema_from_iterator(flat.iter().map(Ok))?;
    let mut decoder = arrow_json::ReaderBuilder::new(Arc::new(schema.clone())).build_decoder()?;
    decoder.serialize(&flat)?;
    Ok(decoder.flush()?.unwrap_or_else(|| RecordBatch::new_empty(Arc::new(schema))))
}

fn flatten(v: &Value) -> Value {
    let Value::Object(m) = v else { return v.clone() };
    let mut out = serde_json::Map::new();
    for (k, x) in m {
        match x {
            Value::Object(inner) => {
                for (ik, iv) in inner {
                    out.insert(format!("{k}.{ik}"), iv.clone());
                }
            }
            _ => {
                out.insert(k.clone(), x.clone());
            }
        }
    }
    Value::Object(out)
}

/// The configuration file `path`, read and checked by `parse` as the CLI does.
fn read_config<T>(path: &Path, parse: impl Fn(&str, &str) -> Result<T, ConfigError>) -> PyResult<T> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| error(anyhow::anyhow!("{}: cannot read: {e}", path.display()), Some(path)))?;
    parse(&path.display().to_string(), &text).map_err(|e| error(e.into(), Some(path)))
}

/// A machine model (`machine.toml`), checked as the CLI checks it.
#[pyclass(frozen, module = "forgemon")]
struct Machine {
    #[pyo3(get)]
    path: PathBuf,
    #[pyo3(get)]
    kind: String,
}

#[pymethods]
impl Machine {
    /// Read and check the machine model at `path`.
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Self> {
        let m = read_config(&path, parse_machine)?;
        Ok(Machine { kind: m.machine.kind().as_str().to_string(), path })
    }

    fn __repr__(&self) -> String {
        format!("Machine('{}', kind='{}')", self.path.display(), self.kind)
    }
}

/// A process sheet (`process.toml`), checked as the CLI checks it; `warnings` are what the
/// CLI prints without stopping.
#[pyclass(frozen, module = "forgemon")]
struct Process {
    #[pyo3(get)]
    path: PathBuf,
    #[pyo3(get)]
    machine: String,
    #[pyo3(get)]
    warnings: Vec<String>,
}

#[pymethods]
impl Process {
    /// Read and check the process sheet at `path`.
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Self> {
        let p = read_config(&path, parse_process_sheet)?;
        Ok(Process { machine: p.value.machine.as_str().to_string(), warnings: p.warnings, path })
    }

    fn __repr__(&self) -> String {
        format!("Process('{}', machine='{}')", self.path.display(), self.machine)
    }
}

/// `forgemon simulate ARGV --json`: its JSON, and its `blows` (or `strikes`) as an IPC
/// stream, energies flattened to `energy.plastic_J`.
#[pyfunction]
fn simulate_json(py: Python<'_>, argv: Vec<String>) -> PyResult<(String, Py<PyBytes>)> {
    let args: forgemon::cli::simulate::SimulateArgs = verb_args("simulate", &argv)?;
    let (json, table) = py
        .detach(|| -> anyhow::Result<(String, Vec<u8>)> {
            let out = forgemon::cli::simulate::output(&args)?;
            let rows = out.get("blows").or_else(|| out.get("strikes")).and_then(Value::as_array).cloned();
            Ok((out.to_string(), ipc(&json_batch(&rows.unwrap_or_default())?)?))
        })
        .map_err(|e| error(e, None))?;
    Ok((json, PyBytes::new(py, &table).unbind()))
}

/// `forgemon replay ARGV --out TMP`: the blows as `forgemon export` has them (the file
/// column names the input), an IPC stream, and the billets as `forgemon history export`
/// has them, Parquet.
#[pyfunction]
fn replay_frames(py: Python<'_>, input: PathBuf, argv: Vec<String>) -> PyResult<(Py<PyBytes>, Py<PyBytes>)> {
    let (blows, billets) = py.detach(|| replay(&input, &argv)).map_err(|e| error(e, Some(&input)))?;
    Ok((PyBytes::new(py, &blows).unbind(), PyBytes::new(py, &billets).unbind()))
}

fn replay(input: &Path, argv: &[String]) -> anyhow::Result<(Vec<u8>, Vec<u8>)> {
    let (mut rows, billets) = replay_rows(input, argv)?;
    for r in &mut rows {
        r.file = input.display().to_string();
    }
    Ok((ipc(&forgemon::cli::export::batch(&rows)?)?, billets))
}

/// `forgemon replay INPUT ARGV --out TMP`, read back: the blows as `forgemon export` reads
/// them from that recording, and the billets as `forgemon history export --table billets
/// --parquet` writes them from a database `forgemon history rebuild` made of it (Parquet
/// bytes).
fn replay_rows(input: &Path, argv: &[String]) -> anyhow::Result<(Vec<forgemon::cli::export::ExportRow>, Vec<u8>)> {
    let dir = tempfile::tempdir()?;
    let out = dir.path().join("replay.mcap");
    let mut full = vec![input.display().to_string(), "--out".into(), out.display().to_string(), "--json".into()];
    full.extend(argv.iter().cloned());
    let args: forgemon::cli::replay::ReplayArgs = verb_args("replay", &full).map_err(|e| anyhow::anyhow!("{e}"))?;
    forgemon::cli::replay::replay_into(&args, std::io::sink(), |_| {})?;
    let (rows, _) = forgemon::cli::export::file_rows(&out)?;
    let (db, parquet) = (dir.path().join("history.sqlite"), dir.path().join("billets.parquet"));
    let (out, db, pq) = (out.display().to_string(), db.display().to_string(), parquet.display().to_string());
    for verb in
        [["rebuild", &out, "--db", &db, "", "", ""], ["export", "--db", &db, "--table", "billets", "--parquet", &pq]]
    {
        let argv: Vec<String> = verb.iter().filter(|a| !a.is_empty()).map(|a| a.to_string()).collect();
        let args: forgemon::cli::history::HistoryArgs =
            verb_args("history", &argv).map_err(|e| anyhow::anyhow!("{e}"))?;
        forgemon::cli::history::run(args)?;
    }
    Ok((rows, std::fs::read(&parquet)?))
}

/// The samples of a recording (or a capture directory), `channels` (all when empty), device
/// time `t_s` within `[t0, t1]`: an IPC stream with `source`, `t_s` and a column per channel.
#[pyfunction]
#[pyo3(signature = (path, channels, t0=None, t1=None))]
fn read_samples(
    py: Python<'_>,
    path: PathBuf,
    channels: Vec<String>,
    t0: Option<f64>,
    t1: Option<f64>,
) -> PyResult<Py<PyBytes>> {
    let bytes = py.detach(|| samples(&path, &channels, t0, t1)).map_err(|e| error(e, Some(&path)))?;
    Ok(PyBytes::new(py, &bytes).unbind())
}

/// The sample batches of a recording, a directory of recordings (a rotated run, in name
/// order) or a capture directory (`blow_NN.csv`, each file its own source), as `replay`
/// tells them apart.
fn batches_of(path: &Path) -> anyhow::Result<Vec<forgemon::signal::sample::SampleBatch>> {
    let mut out = Vec::new();
    if path.is_dir() {
        match forgemon::cli::capture_dir_files(path) {
            Ok(files) => {
                for f in files {
                    forgemon::cli::for_each_capture_batch(&f, |b| {
                        out.push(b);
                        Ok(())
                    })?;
                }
            }
            Err(_) => {
                for f in forgemon::cli::inspect::recordings(path)? {
                    out.extend(batches_of(&f)?);
                }
            }
        }
        return Ok(out);
    }
    for m in RecordReader::open(path)? {
        if let Payload::Samples(b) = m?.payload {
            out.push(b);
        }
    }
    Ok(out)
}

fn samples(path: &Path, channels: &[String], t0: Option<f64>, t1: Option<f64>) -> anyhow::Result<Vec<u8>> {
    use forgemon::signal::sample::Role;
    if let Some(bad) = channels.iter().find(|c| Role::from_column(c).is_none()) {
        let known: Vec<&str> = Role::ALL.iter().map(|r| r.column()).collect();
        anyhow::bail!("channels: '{bad}' is not a channel; the channels are {}", known.join(", "));
    }
    let batches = batches_of(path)?;
    let mut names: Vec<String> = channels.to_vec();
    if names.is_empty() {
        for b in &batches {
            for r in &b.roles {
                if !names.iter().any(|n| n == r.column()) {
                    names.push(r.column().to_string());
                }
            }
        }
    }
    let (lo, hi) = (t0.unwrap_or(f64::NEG_INFINITY), t1.unwrap_or(f64::INFINITY));
    let mut source: Vec<&str> = Vec::new();
    let mut t: Vec<f64> = Vec::new();
    let mut cols: Vec<Vec<Option<f64>>> = vec![Vec::new(); names.len()];
    for b in &batches {
        let at: Vec<Option<usize>> = names.iter().map(|n| b.roles.iter().position(|r| r.column() == n)).collect();
        let width = b.roles.len();
        for i in 0..b.len() {
            let ts = (b.device_time_ns as f64 + i as f64 * b.period_ns) * 1e-9;
            if ts < lo || ts > hi {
                continue;
            }
            source.push(&b.source);
            t.push(ts);
            for (c, a) in cols.iter_mut().zip(&at) {
                c.push(a.map(|k| b.values[i * width + k]));
            }
        }
    }
    let mut fields = vec![Field::new("source", DataType::Utf8, false), Field::new("t_s", DataType::Float64, false)];
    let mut arrays: Vec<ArrayRef> = vec![Arc::new(StringArray::from(source)), Arc::new(Float64Array::from(t))];
    for (n, c) in names.iter().zip(cols) {
        fields.push(Field::new(n, DataType::Float64, true));
        arrays.push(Arc::new(Float64Array::from(c)));
    }
    ipc(&RecordBatch::try_new(Arc::new(Schema::new(fields)), arrays)?)
}

/// `forgemon identify ARGV` (it writes the machine model and its report where ARGV says).
#[pyfunction]
fn identify_run(py: Python<'_>, argv: Vec<String>) -> PyResult<()> {
    let args: forgemon::cli::identify::IdentifyArgs = verb_args("identify", &argv)?;
    py.detach(|| forgemon::cli::identify::run(args)).map_err(|e| error(e, None))?;
    Ok(())
}

/// `forgemon diagnose ARGV` (it writes `report.json` and `report.html` under `--out`).
#[pyfunction]
fn diagnose_run(py: Python<'_>, argv: Vec<String>) -> PyResult<()> {
    let args: forgemon::cli::diagnose::DiagnoseArgs = verb_args("diagnose", &argv)?;
    py.detach(|| forgemon::cli::diagnose::run(args)).map_err(|e| error(e, None))?;
    Ok(())
}

/// The bounds of a source in a recording: its first and last batch's sequence number and
/// device time, ns.
type SourceBounds = (u64, u64, i64, i64);

/// What the fleet re-analysis needs to order, chain and attribute a recording, in one pass:
/// the log time of its first message (ns, UTC), per sample source its bounds, and each
/// recorded blow's device end time `t_end_s` with its log (wall) time, ns, and each recorded
/// billet's device start time `t_start_s` with its log time.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn recording_bounds(
    py: Python<'_>,
    path: PathBuf,
) -> PyResult<(Option<i64>, std::collections::BTreeMap<String, SourceBounds>, Vec<(f64, i64)>, Vec<(f64, i64)>)> {
    py.detach(|| -> anyhow::Result<_> {
        let mut first_log = None;
        let mut sources = std::collections::BTreeMap::new();
        let (mut blows, mut billets) = (Vec::new(), Vec::new());
        for m in RecordReader::open(&path)? {
            let m = m?;
            first_log.get_or_insert(m.log_time_ns);
            match m.payload {
                Payload::Samples(b) => {
                    let end = b.device_time_ns + (b.len().saturating_sub(1) as f64 * b.period_ns) as i64;
                    let e = sources.entry(b.source.clone()).or_insert((b.seq, b.seq, b.device_time_ns, end));
                    e.1 = b.seq;
                    e.3 = end;
                }
                Payload::Result(r) => blows.push((r.t_end_s, m.log_time_ns)),
                Payload::Billet(b) => billets.push((b.t_start_s, m.log_time_ns)),
                _ => {}
            }
        }
        Ok((first_log, sources, blows, billets))
    })
    .map_err(|e| error(e, Some(&path)))
}

/// Re-analyse `files`, one run's recordings in order (each continues the last), as
/// `forgemon replay` replays a directory of them with ARGV: the blows in `forgemon export`'s
/// columns, each attributed to the file that recorded it (matched by its device end time
/// `t_end_s`, which a re-analysis does not move; `recorded[i]` is what `recording_bounds`
/// found in `files[i]`) with that file's wall time; a blow no file recorded keeps the file
/// before it and its replayed time. And the billets.
#[pyfunction]
fn reanalyse_run(
    py: Python<'_>,
    files: Vec<PathBuf>,
    recorded: Vec<Vec<(f64, i64)>>,
    argv: Vec<String>,
) -> PyResult<(Py<PyBytes>, Py<PyBytes>)> {
    let first = files.first().cloned();
    let (blows, billets) = py.detach(|| reanalyse(&files, &recorded, &argv)).map_err(|e| error(e, first.as_deref()))?;
    Ok((PyBytes::new(py, &blows).unbind(), PyBytes::new(py, &billets).unbind()))
}

fn reanalyse(
    files: &[PathBuf],
    recorded_in: &[Vec<(f64, i64)>],
    argv: &[String],
) -> anyhow::Result<(Vec<u8>, Vec<u8>)> {
    // The run as `replay` takes one: a directory of its files in name order.
    let dir = tempfile::tempdir()?;
    let run = dir.path().join("run");
    std::fs::create_dir(&run)?;
    // Each recorded blow by its end time's bits: the first file that recorded it.
    let mut recorded: std::collections::HashMap<u64, (String, i64)> = std::collections::HashMap::new();
    for (i, f) in files.iter().enumerate() {
        let abs = std::fs::canonicalize(f).map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?;
        std::os::unix::fs::symlink(&abs, run.join(format!("{i:06}.mcap")))?;
        let name = f.display().to_string();
        let blows = recorded_in.get(i).map(Vec::as_slice).unwrap_or_default();
        for &(t, wall) in blows {
            recorded.entry(t.to_bits()).or_insert_with(|| (name.clone(), wall));
        }
    }
    let (blows, billets) = replay_rows(&run, argv)?;
    let mut rows = blows;
    let mut last_file = files.first().map(|f| f.display().to_string()).unwrap_or_default();
    for r in &mut rows {
        match recorded.get(&r.t_end_s.to_bits()) {
            Some((file, wall)) => {
                r.file.clone_from(file);
                r.wall_time_ns = *wall;
                r.wall_time = forgemon::cli::export::rfc3339_ns(*wall);
                last_file.clone_from(file);
            }
            None => r.file.clone_from(&last_file),
        }
    }
    Ok((ipc(&forgemon::cli::export::batch(&rows)?)?, billets))
}

#[pymodule]
fn _forgemon(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("ForgemonError", m.py().get_type::<ForgemonError>())?;
    m.add_class::<Machine>()?;
    m.add_class::<Process>()?;
    m.add_function(wrap_pyfunction!(simulate_json, m)?)?;
    m.add_function(wrap_pyfunction!(replay_frames, m)?)?;
    m.add_function(wrap_pyfunction!(read_samples, m)?)?;
    m.add_function(wrap_pyfunction!(identify_run, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose_run, m)?)?;
    m.add_function(wrap_pyfunction!(recording_bounds, m)?)?;
    m.add_function(wrap_pyfunction!(reanalyse_run, m)?)?;
    Ok(())
}
