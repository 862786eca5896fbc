//! `forgemon replay` (docs/interfaces.md §5): a recording (or a directory of them: a rotated run,
//! its unreadable files named and skipped), a capture CSV or a capture directory through
//! exactly the live pipeline; one JSON line per blow (or a table with a line per
//! billet); `--out` records the replay. A recording brings its own machine model, process
//! sheet and service file (alert rules, billet detection); options replace them.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Args;

use super::progress::Progress;
use super::{parse_process_warn, read_text};
use crate::config::history::{Trace, parse_trace_text};
use crate::config::parse_machine;
use crate::config::service::parse_tuning;
use crate::daemon::tuned_config;
use crate::estimate::EncoderDirection;
use crate::physics::process::Process;
use crate::pipeline::{Feeder, Pipeline};
use crate::record::reader::ReadMode;
use crate::record::{Payload, RecordReader, RecordWriter, Rotation};
use crate::session::{
    CHANNELS_CONFIG_NAME, End, MACHINE_CONFIG_NAME, Outcome, PART_CONFIG_NAME, RECIPE_CONFIG_NAME, SERVICE_CONFIG_NAME,
    Session, Stamp, is_die_change_marker, is_new_billet_marker, parse_channels_text,
};
use crate::signal::sample::{Channels, SampleBatch};

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// A recording (.mcap), a directory of them (a rotated run, in name order), a capture
    /// CSV, or a capture directory (blow_01.csv, ...).
    pub input: PathBuf,
    /// The machine model (machine.toml); defaults to the one stored in the recording, or
    /// the capture directory's machine.toml.
    #[arg(long)]
    pub machine: Option<PathBuf>,
    /// The process sheet; defaults to the capture directory's process.toml, or the one
    /// stored in the recording.
    #[arg(long)]
    pub process: Option<PathBuf>,
    /// The service configuration whose alert rules (`[alerts]`) and billet detection
    /// (`[billets]`) to use; defaults to the one stored in the recording, else the defaults.
    #[arg(long)]
    pub service: Option<PathBuf>,
    /// Record the replay (samples, blows, results, alerts, billets, configuration) to this
    /// MCAP file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// One JSON object per blow (docs/interfaces.md §5) instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Judge every blow against this recipe (docs/interfaces.md §9, `forgemon teach`): the §5
    /// `judgement`, and `nok` alerts, as the service would.
    #[arg(long, value_name = "PART.recipe.toml")]
    pub recipe: Option<PathBuf>,
    /// Which way the ram encoder counts: `down` (towards the lower die, docs/interfaces.md §1), `up`
    /// (away from it: read negated), or `auto` (each blow's approach tells); overrides the
    /// service file's `[encoder] direction`.
    #[arg(long, value_name = "auto|down|up", value_parser = parse_direction)]
    pub encoder_direction: Option<EncoderDirection>,
    /// Read each recording's chunks in turn on one thread, instead of ahead and in parallel.
    /// The output is the same, byte for byte.
    #[arg(long)]
    pub sequential: bool,
}

impl ReplayArgs {
    fn read_mode(&self) -> ReadMode {
        if self.sequential { ReadMode::Sequential } else { ReadMode::Parallel }
    }
}

fn parse_direction(s: &str) -> Result<EncoderDirection, String> {
    EncoderDirection::parse(s).ok_or_else(|| format!("must be one of {}", EncoderDirection::WORDS.join(", ")))
}

/// A source of sample batches, whatever the input.
enum Input {
    Files(Vec<PathBuf>),
    /// A recording, streamed in file order (the writer stores each source's samples in
    /// time order), with the samples read ahead while looking for the stored configuration.
    Recording {
        reader: Box<RecordReader>,
        ahead: Vec<SampleBatch>,
        /// The channels no source carried (`session::CHANNELS_CONFIG_NAME`), when recorded.
        absent: Option<Channels>,
        /// What the blows were forged as at the start (`session::PART_CONFIG_NAME`).
        trace: Option<Trace>,
        /// The directory's recordings after this one, in name order (a rotated run).
        rest: Vec<PathBuf>,
        /// Whether unreadable files before this one were skipped.
        skipped: bool,
    },
}

/// The configuration files a recording stores before its first samples, or a capture
/// directory holds.
#[derive(Default)]
struct Stored {
    machine: Option<String>,
    process: Option<String>,
    service: Option<String>,
    /// The recipe the live run judged with (`daemon::RECIPE_CONFIG_NAME`).
    recipe: Option<String>,
    /// The channels none of the live run's sources carried (`session::CHANNELS_CONFIG_NAME`).
    absent: Option<Channels>,
    /// What the blows were forged as at the start (`session::PART_CONFIG_NAME`).
    trace: Option<Trace>,
}

/// A configuration file's text and where it came from (for error messages).
type Origin = (String, String);

/// The option's file, else the stored copy, else nothing.
fn pick(option: &Option<PathBuf>, stored: Option<String>, input: &Path, name: &str) -> anyhow::Result<Option<Origin>> {
    match option {
        Some(p) => Ok(Some((p.display().to_string(), read_text(p)?))),
        None => Ok(stored.map(|t| (format!("{} ({name} stored in it)", input.display()), t))),
    }
}

pub fn run(args: ReplayArgs) -> anyhow::Result<ExitCode> {
    let recipe = args.recipe.as_ref().map(|p| load_recipe(p)).transpose()?;
    // Through `out`: a closed stdout (`| head`) ends the replay quietly (`main`).
    let (status, _) = replay_into(&args, super::out::stdout(), |p| p.set_recipe(recipe))?;
    Ok(status)
}

/// Read and check a recipe file.
pub(crate) fn load_recipe(path: &Path) -> anyhow::Result<crate::recipe::Recipe> {
    Ok(crate::config::recipe::parse_recipe(&path.display().to_string(), &read_text(path)?)?)
}

/// Replay `args.input` with its output to `out`, after `setup` prepared the pipeline (a
/// recipe, the signatures `forgemon teach` keeps); the exit status and the feeder after the
/// end of the input.
pub fn replay_into<W: Write>(
    args: &ReplayArgs,
    out: W,
    setup: impl FnOnce(&mut Pipeline),
) -> anyhow::Result<(ExitCode, Feeder)> {
    let (input, stored) = open_input(&args.input, args.read_mode())?;
    let (mut pipeline, writer, kind) = configured(args, &stored)?;
    setup(&mut pipeline);
    // The recipe the live run judged with, unless the caller gave one.
    if let (None, Some(text)) = (pipeline.recipe(), &stored.recipe) {
        let origin = format!("{} (recipe.toml stored in it)", args.input.display());
        pipeline.set_recipe(crate::daemon::recipe_switch::from_recorded(&origin, text)?);
    }
    if let Some(r) = pipeline.recipe()
        && r.machine != kind.as_str()
    {
        bail!("recipe '{}' was taught on a {} but the machine model is a {}", r.name, r.machine, kind.as_str());
    }
    // The table's recipe column, when the replay judges from the start.
    let judged = pipeline.recipe().is_some();
    let mut replay = Replay {
        session: Session::new(pipeline, writer, Stamp::DeviceEnd),
        outcomes: Vec::new(),
        input: args.input.clone(),
        out: std::io::BufWriter::new(out),
        json: args.json,
        judged,
        progress: Progress::hidden(),
        blows: 0,
        rejected: 0,
        end: End::InputEnded,
    };
    if !args.json {
        writeln!(replay.out, "{}", table_header(judged))?;
    }
    let status = match replay.play(input, args) {
        // The reader of stdout is gone: finish the recording (`--out`), then stop.
        Err(e) if super::out::closed() => {
            let _ = replay.finish();
            return Err(e);
        }
        Err(e) => {
            replay.progress.clear();
            return Err(e);
        }
        Ok(status) => status,
    };
    let feeder = replay.finish()?;
    Ok((status, feeder))
}

/// The pipeline and the recording (`--out`) `args` and the input's stored files make, and
/// the machine's kind.
fn configured(
    args: &ReplayArgs,
    stored: &Stored,
) -> anyhow::Result<(Pipeline, Option<RecordWriter>, crate::physics::machine::MachineKind)> {
    let Some((machine_origin, machine_text)) =
        pick(&args.machine, stored.machine.clone(), &args.input, "machine.toml")?
    else {
        bail!("{}: holds no machine model; give one with --machine M.toml", args.input.display());
    };
    let machine_file = parse_machine(&machine_origin, &machine_text)?;
    let machine = machine_file.machine;
    let effects = machine_file.effect_set();
    let process_text = pick(&args.process, stored.process.clone(), &args.input, "process.toml")?;
    let process: Option<Process> = match &process_text {
        Some((origin, text)) => {
            let p = parse_process_warn(origin, text)?;
            if p.machine != machine.kind() {
                bail!(
                    "{origin}: key 'machine' is \"{}\" but {machine_origin} has kind \"{}\"",
                    p.machine.as_str(),
                    machine.kind().as_str()
                );
            }
            Some(p)
        }
        None => None,
    };
    // The alert rules and billet detection the live run used, unless the caller gives others.
    let service_text = pick(&args.service, stored.service.clone(), &args.input, SERVICE_CONFIG_NAME)?;
    let mut tuning = match &service_text {
        Some((origin, text)) => parse_tuning(origin, text)?,
        None => parse_tuning("defaults", "")?,
    };
    if let Some(d) = args.encoder_direction {
        tuning.encoder_direction = d;
    }
    let writer = match &args.out {
        Some(path) => {
            let mut w = RecordWriter::create(path, Rotation::default())
                .with_context(|| format!("{}: cannot record", path.display()))?;
            w.write_config(0, "machine.toml", &machine_text)?;
            if let Some((_, text)) = &process_text {
                w.write_config(0, "process.toml", text)?;
            }
            if let Some((_, text)) = &service_text {
                w.write_config(0, SERVICE_CONFIG_NAME, text)?;
            }
            Some(w)
        }
        None => None,
    };
    if let Some(name) = crate::estimate::unhonoured(&effects, process.as_ref()) {
        bail!(
            "{machine_origin}: key 'effects.{name}': the estimator carries it in the model fit, which needs the \
             billet's process sheet; give one with --process P.toml"
        );
    }
    let pipeline = Pipeline::new(machine, process, tuned_config(&tuning, &machine)).with_effects(effects);
    Ok((pipeline, writer, machine.kind()))
}

/// The table's columns, with `recipe` (`judged`) when the replay judges with a recipe from
/// the start: each blow's judgement, OK or NOK (`-` on a blow never judged). The last column
/// says why: the alert, the implausible value, or the recipe's reasons.
fn table_header(judged: bool) -> String {
    let recipe = if judged { "  recipe" } else { "" };
    format!(
        "blow  t_contact s     v m/s  kinetic J  plastic J  elastic J  efficiency  class         final kN  h_end mm{recipe}  alert"
    )
}

/// The session (the live service's core) and the output of one replay.
struct Replay<W: Write> {
    session: Session,
    outcomes: Vec<Outcome>,
    /// The input, for the messages.
    input: PathBuf,
    out: W,
    json: bool,
    /// The table has its recipe column (`table_header`).
    judged: bool,
    /// Bytes of the recordings read, on a terminal.
    progress: Progress,
    blows: u64,
    rejected: u64,
    /// How the input ends: a recording where its service stopped, capture files after their
    /// blows (`Session::finish`).
    end: End,
}

impl<W: Write> Replay<W> {
    /// The whole input through the session; the exit status the input's state gives.
    fn play(&mut self, input: Input, args: &ReplayArgs) -> anyhow::Result<ExitCode> {
        let mut status = ExitCode::SUCCESS;
        match input {
            Input::Files(files) => {
                self.end = End::InputEnded;
                for path in files {
                    // A capture without a column is a source without that sensor.
                    super::for_each_capture_batch(&path, |batch| {
                        let absent = Channels::ALL.missing_from(Channels::of(&batch.roles));
                        self.session.set_absent(absent, batch.host_time_ns);
                        self.batch(&batch)
                    })?;
                }
            }
            Input::Recording { reader, ahead, rest, skipped, absent, trace } => {
                self.end = End::Stopped;
                self.progress = Progress::over(std::iter::once(reader.path()).chain(rest.iter().map(PathBuf::as_path)));
                // The channels none of the live run's sources carried, as it recorded them.
                if let Some(absent) = absent {
                    self.session.set_absent(absent, 0);
                }
                // What the live run's first blows were forged as.
                if let Some(trace) = trace {
                    self.session.set_trace(trace, 0);
                }
                for batch in &ahead {
                    self.batch(batch)?;
                }
                status = self.recording(reader, args)?;
                if skipped {
                    status = ExitCode::from(super::inspect::EXIT_CORRUPT_INPUT);
                }
                // A rotated run's next files continue its stream; one that cannot be read
                // is named and skipped.
                for path in rest {
                    match RecordReader::open_with(&path, args.read_mode()) {
                        Ok(reader) => {
                            let s = self.recording(Box::new(reader), args)?;
                            if s != ExitCode::SUCCESS {
                                status = s;
                            }
                        }
                        Err(e) => {
                            self.progress.say(format_args!("forgemon: skipped {}: {e}", path.display()));
                            self.progress.file(&path);
                            self.progress.file_done();
                            status = ExitCode::from(super::inspect::EXIT_CORRUPT_INPUT);
                        }
                    }
                }
            }
        }
        Ok(status)
    }

    /// A recording's messages through the session, its control markers taken where the
    /// live run took them; the exit status its state gives.
    fn recording(&mut self, mut reader: Box<RecordReader>, args: &ReplayArgs) -> anyhow::Result<ExitCode> {
        self.progress.file(reader.path());
        while let Some(m) = reader.next() {
            let m = m?;
            let log_ns = m.log_time_ns;
            match m.payload {
                Payload::Samples(batch) => self.batch(&batch)?,
                // A new billet went into the dies here during the live run.
                Payload::Status(st) if is_new_billet_marker(&st) => {
                    self.session.new_billet(None, log_ns, &mut self.outcomes);
                    self.handle()?;
                }
                // The dies were changed here (`POST /die`).
                Payload::Status(st) if is_die_change_marker(&st) => self.session.dies_changed(log_ns),
                // The live run switched recipes here (`POST /recipe`); a rotated file
                // repeats the same text, which changes nothing.
                Payload::Config(c) if c.name == RECIPE_CONFIG_NAME && args.recipe.is_none() => {
                    let origin = format!("{} (recipe.toml stored in it)", args.input.display());
                    let recipe = crate::daemon::recipe_switch::from_recorded(&origin, &c.text)?;
                    self.session.set_recipe(recipe, &c.text, log_ns);
                }
                // The live run reloaded its machine model here (SIGHUP, after `diagnose
                // --adopt`); a rotated file repeats the same text, which changes nothing.
                Payload::Config(c) if c.name == MACHINE_CONFIG_NAME && args.machine.is_none() => {
                    let origin = format!("{} (machine.toml stored in it)", args.input.display());
                    self.session.set_model(&origin, &c.text, log_ns).map_err(anyhow::Error::msg)?;
                }
                // The part, lot or die set changed here (`[part]` at the start, a new
                // billet's own); a rotated file repeats the same, which changes nothing.
                Payload::Config(c) if c.name == PART_CONFIG_NAME => {
                    let trace = parse_trace_text(&c.text)
                        .map_err(|why| anyhow::anyhow!("{} (part.toml stored in it): {why}", args.input.display()))?;
                    self.session.set_trace(trace, log_ns);
                }
                // The live run reloaded its alert rules here (SIGHUP); a rotated file
                // repeats the same text, which changes nothing.
                Payload::Config(c) if c.name == SERVICE_CONFIG_NAME && args.service.is_none() => {
                    let origin = format!("{} (service.toml stored in it)", args.input.display());
                    self.session.set_alerts(parse_tuning(&origin, &c.text)?.alerts, &c.text, log_ns);
                }
                _ => {}
            }
            self.recorded()?;
            self.progress.at(reader.report().bytes_recovered);
        }
        self.progress.file_done();
        if !reader.report().complete {
            self.progress.say(format_args!("forgemon: {}", reader.report()));
        }
        Ok(super::inspect::input_status(reader.report()))
    }

    /// A batch through the session: recorded (with `--out`), merged, fed.
    fn batch(&mut self, batch: &SampleBatch) -> anyhow::Result<()> {
        self.session.batch(batch, &mut self.outcomes);
        self.handle()
    }

    /// A failed write to `--out` stops the replay.
    fn recorded(&mut self) -> anyhow::Result<()> {
        match self.session.take_record_errors().into_iter().next() {
            Some((what, e)) => Err(anyhow::Error::new(e).context(format!("recording {what}"))),
            None => Ok(()),
        }
    }

    /// Print the session's outcomes.
    fn handle(&mut self) -> anyhow::Result<()> {
        self.recorded()?;
        for o in std::mem::take(&mut self.outcomes) {
            match o {
                Outcome::Blow { estimate, .. } => {
                    self.blows += 1;
                    if self.json {
                        writeln!(self.out, "{}", serde_json::to_string(&estimate)?)?;
                    } else {
                        writeln!(self.out, "{}", table_row(&estimate, self.judged))?;
                    }
                }
                Outcome::Billet { summary, .. } => {
                    if !self.json {
                        writeln!(self.out, "{summary}")?;
                    }
                }
                Outcome::Rejected { cut, error } => {
                    self.rejected += 1;
                    // A directory's blow is placed in its file (`cli::for_each_capture_batch`).
                    let file = cut.source.strip_prefix(super::CAPTURE_SOURCE).and_then(|n| n.strip_prefix('/'));
                    let place = match file {
                        Some(name) if self.input.is_dir() => self.input.join(name),
                        _ => self.input.clone(),
                    };
                    self.progress.say(format_args!(
                        "forgemon: {}: blow at t = {:.6} s not estimated: {error}",
                        place.display(),
                        cut.t_contact_s
                    ));
                }
                Outcome::NewBillet | Outcome::Forged(_) => {}
            }
        }
        Ok(())
    }

    /// The end of the input: the last blow and billet closed, the recording finished.
    fn finish(mut self) -> anyhow::Result<Feeder> {
        let files = self.session.finish(self.end, 0, &mut self.outcomes);
        self.handle()?;
        self.progress.clear();
        self.out.flush()?;
        for f in files? {
            eprintln!("forgemon: recorded {}", f.display());
        }
        let mut feeder = self.session.into_feeder();
        let reversed = feeder.pipeline_mut().reversed_encoder_blows();
        if reversed > 0 {
            eprintln!(
                "forgemon: the ram encoder counts up (away from the die) in {reversed} blows: read negated; \
                 --encoder-direction up (or [encoder] direction = \"up\") says so"
            );
        }
        let s = feeder.pipeline_mut().segment_stats();
        eprintln!(
            "forgemon: replayed {} samples: {} blows, {} not estimated, {} triggers without contact, {} batches dropped",
            feeder.samples(),
            self.blows,
            self.rejected,
            s.triggers_without_contact,
            s.batches_dropped
        );
        Ok(feeder)
    }
}

/// A blow's row of the table; with its recipe column when `judged` (`table_header`). A blow
/// judged without the column (a recipe the recording switched to later) says OK or NOK in
/// the last column.
fn table_row(e: &crate::estimate::BlowEstimate, judged: bool) -> String {
    let verdict = match &e.judgement {
        Some(j) if j.ok => "OK",
        Some(_) => "NOK",
        None => "-",
    };
    let mut why: Vec<String> = match (&e.alert, &e.implausible) {
        (Some(a), _) => vec![a.reason.clone()],
        (None, Some(i)) => vec![i.reason.clone()],
        (None, None) => Vec::new(),
    };
    match &e.judgement {
        Some(j) if !judged => {
            why.push(format!("recipe {verdict}{}", j.reasons.iter().map(|r| format!("; {r}")).collect::<String>()))
        }
        Some(j) if e.alert.is_none() && e.implausible.is_none() => why.extend(j.reasons.iter().cloned()),
        _ => {}
    }
    let recipe = if judged { format!("  {verdict:<6}") } else { String::new() };
    format!(
        "{:>4}  {:>12.4}  {:>6.3}  {:>9}  {:>9}  {:>9}  {:>10}  {:<12}  {:>8.0}  {:>8}{recipe}  {}",
        e.blow,
        e.t_contact_s,
        e.v_impact_mps,
        or_dash(e.kinetic_in_j, 0),
        or_dash(e.plastic_j, 0),
        or_dash(e.elastic_j, 0),
        or_dash(e.efficiency, 3),
        e.class.as_str(),
        e.final_load_n / 1e3,
        e.h_end_m.map_or("-".to_string(), |h| format!("{:.2}", h * 1e3)),
        why.join("; "),
    )
}

/// Classify the input and read the configuration it stores: a recording's (read up to its
/// first samples), a capture directory's machine.toml and process.toml, or, for a
/// directory of recordings (a rotated run), its first readable file's.
fn open_input(path: &Path, mode: ReadMode) -> anyhow::Result<(Input, Stored)> {
    let recordings = path.is_dir() && super::capture_dir_files(path).is_err();
    if let Some(files) = recordings.then(|| super::inspect::recordings(path).ok()).flatten() {
        let (mut files, mut skipped) = (files.into_iter(), false);
        while let Some(first) = files.next() {
            match open_recording(&first, mode) {
                Ok((reader, ahead, stored)) => {
                    let (absent, trace) = (stored.absent, stored.trace.clone());
                    let rest = files.collect();
                    return Ok((Input::Recording { reader, ahead, rest, skipped, absent, trace }, stored));
                }
                Err(e) => {
                    eprintln!("forgemon: skipped {}: {}", first.display(), super::error_message(&e));
                    skipped = true;
                }
            }
        }
        bail!("{}: none of its recordings can be read", path.display());
    }
    if path.is_dir() {
        let read = |name: &str| -> anyhow::Result<Option<String>> {
            let p = path.join(name);
            p.exists().then(|| read_text(&p)).transpose()
        };
        let stored = Stored {
            machine: read("machine.toml")?,
            process: read("process.toml")?,
            service: None,
            recipe: None,
            absent: None,
            trace: None,
        };
        return Ok((Input::Files(super::capture_dir_files(path)?), stored));
    }
    let name = path.to_string_lossy();
    if name.ends_with(".mcap") || name.ends_with(".mcap.part") {
        let (reader, ahead, stored) = open_recording(path, mode)?;
        let (absent, trace) = (stored.absent, stored.trace.clone());
        return Ok((Input::Recording { reader, ahead, rest: Vec::new(), skipped: false, absent, trace }, stored));
    }
    if !path.exists() {
        bail!("{}: no such file or directory", path.display());
    }
    Ok((Input::Files(vec![path.to_path_buf()]), Stored::default()))
}

/// A recording, with the configuration it stores before its first samples and the samples
/// read ahead while looking for it.
fn open_recording(path: &Path, mode: ReadMode) -> anyhow::Result<(Box<RecordReader>, Vec<SampleBatch>, Stored)> {
    let mut reader = RecordReader::open_with(path, mode)?;
    let mut stored = Stored::default();
    let mut ahead = Vec::new();
    // Configuration is written before the samples; read up to the first batch of them.
    for m in reader.by_ref() {
        match m?.payload {
            Payload::Samples(b) => {
                ahead.push(b);
                break;
            }
            Payload::Config(c) if c.name == "machine.toml" => stored.machine = Some(c.text),
            Payload::Config(c) if c.name == "process.toml" => stored.process = Some(c.text),
            Payload::Config(c) if c.name == SERVICE_CONFIG_NAME => stored.service = Some(c.text),
            Payload::Config(c) if c.name == RECIPE_CONFIG_NAME => stored.recipe = Some(c.text),
            Payload::Config(c) if c.name == CHANNELS_CONFIG_NAME => stored.absent = parse_channels_text(&c.text),
            Payload::Config(c) if c.name == PART_CONFIG_NAME => {
                let trace = parse_trace_text(&c.text)
                    .map_err(|why| anyhow::anyhow!("{} ({PART_CONFIG_NAME} stored in it): {why}", path.display()))?;
                stored.trace = Some(trace);
            }
            _ => {}
        }
    }
    Ok((Box::new(reader), ahead, stored))
}

/// A figure of the table, or `-` where the blow has none (an incomplete blow).
fn or_dash(v: Option<f64>, decimals: usize) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.decimals$}"))
}
