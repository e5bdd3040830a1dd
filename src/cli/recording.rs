//! `omnirow recording check FILE...` and `omnirow recording repair IN OUT`.
//!
//! Owns the command-line side of damaged recordings: `check` reports, per file, its frames,
//! time span, intact and damaged chunks, whether its summary is there, and every skipped
//! region (exit 0 when every file is intact, 1 when one is damaged or cut short, 2 when one
//! cannot be read); `repair` writes every intact message of a damaged file, with its
//! attachments and a valid summary, into a new file that ROS 2 tools and Foxglove open. Both
//! read through [`crate::record::salvage`], as replay does.

use crate::record::salvage::{Damage, Event, Salvage, SalvageReport, SummaryState};
use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use mcap::records::Record;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Debug, Subcommand)]
pub enum RecordingCommand {
    /// Report per file: frames, time span, intact and damaged chunks, summary, skipped regions.
    /// Exit 0: all intact; 1: some file damaged or cut short; 2: some file unreadable.
    Check(CheckArgs),
    /// Write every intact message of IN (attachments too) into OUT with a valid summary.
    Repair(RepairArgs),
}

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// MCAP files.
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// One JSON object per file instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct RepairArgs {
    /// The damaged recording.
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// The repaired recording (must not exist).
    #[arg(value_name = "OUT")]
    pub output: PathBuf,
}

pub fn run(cmd: RecordingCommand) -> anyhow::Result<ExitCode> {
    match cmd {
        RecordingCommand::Check(a) => check(&a),
        RecordingCommand::Repair(a) => repair(&a),
    }
}

/// What a pass over a file counted.
#[derive(Debug, Default)]
struct Tally {
    /// topic -> (schema name, messages)
    topics: BTreeMap<String, (String, u64)>,
    channels: HashMap<u16, String>,
    schemas: HashMap<u16, String>,
    /// Messages on channels with no intact definition.
    orphans: u64,
    first_ns: Option<u64>,
    last_ns: Option<u64>,
    attachments: u64,
}

impl Tally {
    fn record(&mut self, r: &Record<'_>) {
        match r {
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name.clone());
            }
            Record::Channel(c) => {
                let schema = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                self.channels.insert(c.id, c.topic.clone());
                self.topics.entry(c.topic.clone()).or_insert((schema, 0));
            }
            Record::Message { header, .. } => {
                match self
                    .channels
                    .get(&header.channel_id)
                    .and_then(|t| self.topics.get_mut(t))
                {
                    Some(t) => t.1 += 1,
                    None => self.orphans += 1,
                }
                let t = header.log_time;
                self.first_ns = Some(self.first_ns.map_or(t, |f| f.min(t)));
                self.last_ns = Some(self.last_ns.map_or(t, |l| l.max(t)));
            }
            Record::Attachment { .. } => self.attachments += 1,
            _ => {}
        }
    }

    /// Messages on image channels (the frames).
    fn frames(&self) -> u64 {
        self.topics
            .values()
            .filter(|(schema, _)| is_image_schema(schema))
            .map(|(_, n)| n)
            .sum()
    }

    /// Frames a damaged region held, if the indexes tell.
    fn frames_held(&self, d: &Damage) -> Option<u64> {
        let held = d.held.as_ref()?;
        Some(
            held.iter()
                .filter(|(ch, _)| {
                    self.channels
                        .get(ch)
                        .and_then(|t| self.topics.get(t))
                        .is_some_and(|(s, _)| is_image_schema(s))
                })
                .map(|(_, n)| n)
                .sum(),
        )
    }
}

fn is_image_schema(name: &str) -> bool {
    matches!(
        name,
        "sensor_msgs/msg/Image" | "foxglove_msgs/msg/RawImage" | "foxglove.RawImage"
    )
}

fn open(path: &Path) -> anyhow::Result<Salvage<File>> {
    let f = File::open(path).with_context(|| format!("{}", path.display()))?;
    Salvage::new(f).with_context(|| format!("{}", path.display()))
}

fn summary_text(s: &Option<SummaryState>) -> String {
    match s {
        Some(SummaryState::Intact) => "intact".into(),
        Some(SummaryState::Absent) => "none (the writer wrote none)".into(),
        Some(SummaryState::Damaged(why)) => format!("damaged ({why})"),
        Some(SummaryState::Missing) | None => "missing (the file was cut short)".into(),
    }
}

fn check(a: &CheckArgs) -> anyhow::Result<ExitCode> {
    let mut worst = 0u8;
    for path in &a.files {
        let result = open(path).and_then(|mut r| {
            let mut tally = Tally::default();
            while let Some(ev) = r
                .next_event()
                .with_context(|| format!("{}", path.display()))?
            {
                if let Event::Record(rec) = ev {
                    tally.record(&rec);
                }
            }
            Ok((tally, r.report().clone()))
        });
        match result {
            Ok((tally, report)) => {
                if !report.is_clean() {
                    worst = worst.max(1);
                }
                if a.json {
                    println!("{}", check_json(path, &tally, &report));
                } else {
                    print!("{}", check_text(path, &tally, &report));
                }
            }
            Err(e) => {
                worst = 2;
                if a.json {
                    let v = serde_json::json!({"file": path, "error": format!("{e:#}")});
                    println!("{v}");
                } else {
                    println!("{}: cannot be read: {e:#}", path.display());
                }
            }
        }
    }
    Ok(ExitCode::from(worst))
}

fn span_s(t: &Tally) -> f64 {
    match (t.first_ns, t.last_ns) {
        (Some(a), Some(b)) => (b - a) as f64 * 1e-9,
        _ => 0.0,
    }
}

fn check_text(path: &Path, t: &Tally, r: &SalvageReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let verdict = if r.is_clean() {
        "intact"
    } else if r.damage.is_empty() && r.duplicate_chunks == 0 {
        "cut short"
    } else {
        "damaged"
    };
    let _ = writeln!(s, "{}: {verdict}", path.display());
    let _ = writeln!(
        s,
        "  frames: {}   messages: {}   time span: {:.3} s{}",
        t.frames(),
        t.topics.values().map(|(_, n)| n).sum::<u64>() + t.orphans,
        span_s(t),
        match (t.first_ns, t.last_ns) {
            (Some(a), Some(b)) => format!(" ({a} .. {b} ns)"),
            _ => String::new(),
        }
    );
    for (topic, (schema, n)) in &t.topics {
        let _ = writeln!(s, "    {topic} ({schema}): {n}");
    }
    if t.orphans > 0 {
        let _ = writeln!(
            s,
            "    {} messages on channels whose definition was lost",
            t.orphans
        );
    }
    let _ = writeln!(
        s,
        "  chunks: {} intact, {} damaged{}   summary: {}   end: {}",
        r.chunks_intact,
        r.chunks_damaged,
        if r.duplicate_chunks > 0 {
            format!(", {} duplicated", r.duplicate_chunks)
        } else {
            String::new()
        },
        summary_text(&r.summary),
        if r.complete {
            "footer and end magic present"
        } else {
            "cut short"
        }
    );
    for d in &r.damage {
        let held = match t.frames_held(d) {
            Some(n) => format!("{n} frames"),
            None => "an unknown number of frames".into(),
        };
        let _ = writeln!(
            s,
            "  skipped bytes {}..{} ({} bytes){}: {}; held {held}",
            d.offset,
            d.offset + d.len,
            d.len,
            if d.cut_short { " at the cut" } else { "" },
            d.reason
        );
    }
    s
}

fn check_json(path: &Path, t: &Tally, r: &SalvageReport) -> serde_json::Value {
    let topics: serde_json::Map<String, serde_json::Value> = t
        .topics
        .iter()
        .map(|(k, (schema, n))| {
            (
                k.clone(),
                serde_json::json!({"schema": schema, "messages": n}),
            )
        })
        .collect();
    let damage: Vec<serde_json::Value> = r
        .damage
        .iter()
        .map(|d| {
            serde_json::json!({
                "offset": d.offset,
                "len": d.len,
                "reason": d.reason,
                "frames": t.frames_held(d),
                "cut_short": d.cut_short,
            })
        })
        .collect();
    serde_json::json!({
        "file": path,
        "intact": r.is_clean(),
        "complete": r.complete,
        "summary": summary_text(&r.summary),
        "frames": t.frames(),
        "topics": topics,
        "orphan_messages": t.orphans,
        "first_ns": t.first_ns,
        "last_ns": t.last_ns,
        "span_s": span_s(t),
        "chunks_intact": r.chunks_intact,
        "chunks_damaged": r.chunks_damaged,
        "duplicate_chunks": r.duplicate_chunks,
        "damage": damage,
    })
}

/// Rewrites what `Salvage` yields into a fresh MCAP file.
struct Rewriter {
    writer: mcap::Writer<BufWriter<File>>,
    schemas: HashMap<u16, u16>,
    channels: HashMap<u16, u16>,
    messages: u64,
    dropped: u64,
}

impl Rewriter {
    fn record(&mut self, r: Record<'_>) -> Result<(), mcap::McapError> {
        match r {
            Record::Schema { header, data } => {
                let id = self
                    .writer
                    .add_schema(&header.name, &header.encoding, &data)?;
                self.schemas.insert(header.id, id);
            }
            Record::Channel(c) => {
                let schema = match c.schema_id {
                    0 => Some(0),
                    s => self.schemas.get(&s).copied(),
                };
                if let Some(schema) = schema {
                    let id = self.writer.add_channel(
                        schema,
                        &c.topic,
                        &c.message_encoding,
                        &c.metadata,
                    )?;
                    self.channels.insert(c.id, id);
                }
            }
            Record::Message { header, data } => match self.channels.get(&header.channel_id) {
                Some(&channel_id) => {
                    let h = mcap::records::MessageHeader {
                        channel_id,
                        ..header
                    };
                    self.writer.write_to_known_channel(&h, &data)?;
                    self.messages += 1;
                }
                None => self.dropped += 1,
            },
            Record::Attachment { header, data, .. } => {
                self.writer.attach(&mcap::Attachment {
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data,
                })?;
            }
            Record::Metadata(m) => self.writer.write_metadata(&m)?,
            _ => {}
        }
        Ok(())
    }
}

fn repair(a: &RepairArgs) -> anyhow::Result<ExitCode> {
    if a.output.exists() {
        bail!("{} exists: repair writes a new file", a.output.display());
    }
    let mut reader = open(&a.input)?;
    // The profile of the original header, when it survived (it comes first, at byte 8).
    let mut profile = String::new();
    {
        let mut probe = open(&a.input)?;
        while let Some(ev) = probe.next_event()? {
            match ev {
                Event::Record(Record::Header(h)) => {
                    profile = h.profile;
                    break;
                }
                Event::Record(Record::Schema { .. } | Record::Channel(_)) => {}
                _ => break,
            }
        }
    }
    let out = File::options()
        .write(true)
        .create_new(true)
        .open(&a.output)
        .with_context(|| format!("{}", a.output.display()))?;
    let result = (|| -> anyhow::Result<Rewriter> {
        let writer = mcap::WriteOptions::new()
            .compression(None)
            .profile(profile)
            .library(concat!("omnirow-", env!("CARGO_PKG_VERSION"), " repair"))
            .chunk_size(Some(1 << 20))
            .create(BufWriter::with_capacity(1 << 20, out))?;
        let mut rw = Rewriter {
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            messages: 0,
            dropped: 0,
        };
        while let Some(ev) = reader.next_event()? {
            match ev {
                Event::Record(r) => rw.record(r)?,
                // One chunk out per chunk in, as the recorder writes them.
                Event::ChunkEnd => rw.writer.flush()?,
                Event::Damage(d) => eprintln!(
                    "{}: skipped bytes {}..{}: {}",
                    a.input.display(),
                    d.offset,
                    d.offset + d.len,
                    d.reason
                ),
            }
        }
        rw.writer.finish()?;
        Ok(rw)
    })();
    let rw = match result {
        Ok(rw) => rw,
        Err(e) => {
            let _ = std::fs::remove_file(&a.output);
            return Err(e.context(format!(
                "repairing {} into {}",
                a.input.display(),
                a.output.display()
            )));
        }
    };
    let file = rw
        .writer
        .into_inner()
        .into_inner()
        .map_err(|e| e.into_error())?;
    file.sync_all()
        .with_context(|| format!("{}", a.output.display()))?;
    let r = reader.report();
    println!(
        "{}: wrote {} messages from {} intact chunks into {}; skipped {} damaged regions ({} bytes){}{}",
        a.input.display(),
        rw.messages,
        r.chunks_intact,
        a.output.display(),
        r.damage.len(),
        r.damage.iter().map(|d| d.len).sum::<u64>(),
        if r.duplicate_chunks > 0 {
            format!(", {} duplicated chunks", r.duplicate_chunks)
        } else {
            String::new()
        },
        if rw.dropped > 0 {
            format!(
                "; {} messages dropped: their channel's definition was lost",
                rw.dropped
            )
        } else {
            String::new()
        }
    );
    Ok(ExitCode::SUCCESS)
}
