//! Reading MCAP files that may be damaged: every record of every intact chunk, nothing from a
//! damaged one, and a report of what was skipped.
//!
//! Owns [`Salvage`], the reader behind replay, `omnirow recording check` and `repair`. It walks
//! the data section record by record (parsing each with the `mcap` crate) and trusts a chunk
//! only when its lengths agree, its CRC matches and every record inside it parses. A chunk that
//! fails is skipped and reading resynchronises at the next intact chunk: through the summary's
//! chunk index when the summary is intact (its CRC matches), else by scanning forward for the
//! next record that is a valid chunk. Adjacent skipped bytes form one [`Damage`] region,
//! reported once with its file offset and, where the message indexes tell, the messages it
//! held. Only a file without its footer and end magic is "cut short". A chunk identical to one
//! of the last few read (a block written twice) is skipped as a duplicate.
//!
//! Compressed chunks (zstd and lz4, as ros2 bag and Foxglove write them) are decompressed into
//! a buffer of their own; one that does not decompress to its stated size and CRC is damage
//! like any other.

use mcap::records::{op, Record};
use std::collections::BTreeMap;
use std::io::{BufReader, Read, Seek, SeekFrom};

/// Opcode and length in front of every record.
const FRAMING: u64 = 9;
/// Footer record (opcode, length, three fields) and end magic.
const FOOTER_AND_MAGIC: u64 = 9 + 20 + 8;
/// Chunk header bytes before the compression string and after it.
const CHUNK_FIXED: u64 = 8 + 8 + 8 + 4 + 4 + 8;
/// Longest compression name a chunk header may carry.
const MAX_COMPRESSION_NAME: u64 = 16;
/// Largest non-chunk record read from the data section (a damaged length is not allocated).
const MAX_SMALL_RECORD: u64 = 64 << 20;
/// Largest attachment or metadata record.
const MAX_ATTACHMENT: u64 = 1 << 30;
/// Largest uncompressed size a compressed chunk may claim (a damaged size is not allocated).
const MAX_UNCOMPRESSED_CHUNK: u64 = 1 << 30;
/// Scan window when looking for the next chunk.
const SCAN_WINDOW: usize = 1 << 20;
/// How far a file without either magic is searched for a chunk before it is called no MCAP.
const MAX_SCAN_WITHOUT_MAGIC: u64 = 64 << 20;
/// How many recent chunks a duplicate is looked for among.
const RECENT_CHUNKS: usize = 8;

/// Errors that stop reading (damage does not: it is skipped and reported).
#[derive(Debug, thiserror::Error)]
pub enum SalvageError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("not an MCAP file (no MCAP magic at its start or end, and no chunk)")]
    NotMcap,
}

/// Messages per channel id.
pub type Held = BTreeMap<u16, u64>;

/// A skipped region of the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// File offset of the first skipped byte.
    pub offset: u64,
    /// Bytes skipped.
    pub len: u64,
    /// What was wrong with the first record of the region.
    pub reason: String,
    /// Messages per channel id that the region held, from the message indexes; `None` when
    /// they are unknown (no intact index describes the region).
    pub held: Option<Held>,
    /// The region runs to the end of a file that was cut short.
    pub cut_short: bool,
}

impl Damage {
    /// Messages of `channel` the region held, if known.
    pub fn held_on(&self, channel: u16) -> Option<u64> {
        self.held
            .as_ref()
            .map(|h| h.get(&channel).copied().unwrap_or(0))
    }
}

/// The state of a file's summary section.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SummaryState {
    /// Present and intact (CRC matches, every record parses): its chunk index is used.
    Intact,
    /// The footer says there is none.
    Absent,
    /// Present but unusable (the reason).
    Damaged(String),
    /// No footer at all: the file was cut short before its summary was written.
    Missing,
}

/// What reading found, so far (complete once [`Salvage::next_event`] returned `None`).
#[derive(Debug, Clone, Default)]
pub struct SalvageReport {
    pub file_len: u64,
    /// Footer and end magic present.
    pub complete: bool,
    pub summary: Option<SummaryState>,
    /// Chunks the summary indexes (intact summary only).
    pub indexed_chunks: Option<u64>,
    pub chunks_intact: u64,
    /// Damaged chunks: exact with an intact summary (indexed chunks not read), else the
    /// skipped records that began like a chunk.
    pub chunks_damaged: u64,
    pub duplicate_chunks: u64,
    pub damage: Vec<Damage>,
}

impl SalvageReport {
    /// Nothing skipped, nothing missing.
    pub fn is_clean(&self) -> bool {
        self.complete && self.damage.is_empty() && self.duplicate_chunks == 0
    }
}

/// What [`Salvage::next_event`] yields.
#[derive(Debug)]
pub enum Event<'a> {
    /// A record of the data section (from an intact chunk or outside any chunk) — or, first,
    /// a schema or channel of an intact summary (so that channels defined in a damaged chunk
    /// are still known). Chunks, message indexes and the summary section are not yielded.
    Record(Record<'a>),
    /// The last record of an intact chunk was yielded.
    ChunkEnd,
    /// A region was skipped (also in [`Salvage::report`]).
    Damage(&'a Damage),
}

/// A chunk as the summary indexes it.
#[derive(Debug, Clone)]
struct Indexed {
    start: u64,
    len: u64,
    message_indexes: BTreeMap<u16, u64>,
}

/// A schema or channel of the summary.
enum Definition {
    Schema(mcap::records::SchemaHeader, Vec<u8>),
    Channel(mcap::records::Channel),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct ChunkKey {
    start: u64,
    end: u64,
    crc: u32,
    size: u64,
}

enum State {
    /// Yielding the summary's definitions.
    Definitions(usize),
    /// Reading the top-level record at `pos`.
    TopLevel,
    /// Yielding the records of the chunk in `rec[at..end]`, or in `unpacked[at..end]` when
    /// the chunk was compressed.
    InChunk {
        at: usize,
        end: usize,
        unpacked: bool,
    },
    Done,
}

/// Reads an MCAP file past damage. See the module documentation.
pub struct Salvage<R: Read + Seek> {
    src: BufReader<R>,
    /// Position of `src` (tracked, so that sequential reads never seek).
    src_pos: u64,
    /// Offset of the next top-level record.
    pos: u64,
    /// End of the data section: the summary's start when intact, the footer's when present,
    /// else the file's end.
    data_end: u64,
    /// Chunks of an intact summary, by offset; empty when the file is scanned.
    index: Vec<Indexed>,
    /// The summary's schemas and channels (intact summary only).
    definitions: Vec<Definition>,
    /// Body of the current top-level record.
    rec: Vec<u8>,
    /// The records of the current chunk when it was compressed.
    unpacked: Vec<u8>,
    scan: Vec<u8>,
    state: State,
    /// End of the last intact chunk: a scan for the next chunk starts here.
    trusted: u64,
    /// The `trusted` offset a scan last started from.
    rescanned_from: Option<u64>,
    /// Whether a chunk has been seen (then messages outside chunks are damage).
    chunked: bool,
    recent: [Option<ChunkKey>; RECENT_CHUNKS],
    recent_next: usize,
    /// The region being skipped, reported when reading is back on track.
    open: Option<Damage>,
    /// Index in `report.damage` of a region to yield next.
    emit: Option<usize>,
    report: SalvageReport,
}

impl<R: Read + Seek> Salvage<R> {
    /// Checks the magic (at the start, or at the end when the start is damaged) and reads the
    /// footer and summary.
    pub fn new(src: R) -> Result<Self, SalvageError> {
        let mut src = BufReader::with_capacity(64 << 10, src);
        let file_len = src.seek(SeekFrom::End(0))?;
        let mut s = Salvage {
            src,
            src_pos: file_len,
            pos: 8,
            data_end: file_len,
            index: Vec::new(),
            definitions: Vec::new(),
            rec: Vec::new(),
            unpacked: Vec::new(),
            scan: Vec::new(),
            state: State::TopLevel,
            trusted: 8,
            rescanned_from: None,
            chunked: false,
            recent: [None; RECENT_CHUNKS],
            recent_next: 0,
            open: None,
            emit: None,
            report: SalvageReport {
                file_len,
                ..SalvageReport::default()
            },
        };
        let mut head = [0u8; 8];
        let start_ok = s.read_at(0, &mut head)? == 8 && head == *mcap::MAGIC;
        let mut tail = [0u8; FOOTER_AND_MAGIC as usize];
        let tail_at = file_len.saturating_sub(FOOTER_AND_MAGIC);
        let tail_ok = file_len >= 8 + FOOTER_AND_MAGIC
            && s.read_at(tail_at, &mut tail)? == tail.len()
            && tail[29..] == *mcap::MAGIC;
        if !start_ok && !tail_ok {
            // Both ends damaged: an MCAP still, if a valid chunk is found near the start.
            s.data_end = file_len.min(8 + MAX_SCAN_WITHOUT_MAGIC);
            let found = s.scan_for_chunk(8, u64::MAX)?;
            s.data_end = file_len;
            if found >= file_len.min(8 + MAX_SCAN_WITHOUT_MAGIC) {
                return Err(SalvageError::NotMcap);
            }
        }
        let footer = if tail_ok && tail[0] == op::FOOTER {
            match mcap::parse_record(op::FOOTER, &tail[9..29]) {
                Ok(Record::Footer(f)) => Some(f),
                _ => None,
            }
        } else {
            None
        };
        let summary = match footer {
            None => SummaryState::Missing,
            Some(f) => {
                s.report.complete = true;
                s.data_end = tail_at;
                if f.summary_start == 0 {
                    SummaryState::Absent
                } else {
                    match s.read_summary(f.summary_start, f.summary_crc, tail_at, &tail) {
                        Ok(()) => {
                            s.data_end = f.summary_start;
                            s.report.indexed_chunks = Some(s.index.len() as u64);
                            SummaryState::Intact
                        }
                        Err(why) => {
                            s.index.clear();
                            SummaryState::Damaged(why)
                        }
                    }
                }
            }
        };
        s.report.summary = Some(summary);
        s.chunked = !s.index.is_empty();
        if !s.definitions.is_empty() {
            s.state = State::Definitions(0);
        }
        Ok(s)
    }

    /// What was found so far.
    pub fn report(&self) -> &SalvageReport {
        &self.report
    }

    /// The next record, chunk end or skipped region; `None` at the end of the data.
    pub fn next_event(&mut self) -> Result<Option<Event<'_>>, SalvageError> {
        loop {
            if let Some(i) = self.emit.take() {
                return Ok(Some(Event::Damage(&self.report.damage[i])));
            }
            match self.state {
                State::Definitions(i) => {
                    if i + 1 < self.definitions.len() {
                        self.state = State::Definitions(i + 1);
                    } else {
                        self.state = State::TopLevel;
                    }
                    let record = match &self.definitions[i] {
                        Definition::Schema(header, data) => Record::Schema {
                            header: header.clone(),
                            data: std::borrow::Cow::Borrowed(data),
                        },
                        Definition::Channel(c) => Record::Channel(c.clone()),
                    };
                    return Ok(Some(Event::Record(record)));
                }
                State::InChunk { at, end, unpacked } => {
                    if at >= end {
                        self.state = State::TopLevel;
                        return Ok(Some(Event::ChunkEnd));
                    }
                    let records = if unpacked { &self.unpacked } else { &self.rec };
                    let Some((opcode, body_at, next)) = frame(&records[..end], at) else {
                        unreachable!("chunk records were checked when the chunk was read")
                    };
                    self.state = State::InChunk {
                        at: next,
                        end,
                        unpacked,
                    };
                    let body = &records[body_at..next];
                    let record = mcap::parse_record(opcode, body)
                        .expect("chunk records were parsed when the chunk was read");
                    return Ok(Some(Event::Record(record)));
                }
                State::Done => return Ok(None),
                State::TopLevel => {
                    if let Some(record_at) = self.top_level()? {
                        let (opcode, body) = (self.rec[0], &self.rec[record_at..]);
                        let record = mcap::parse_record(opcode, body)
                            .expect("top-level records are parsed when read");
                        return Ok(Some(Event::Record(record)));
                    }
                }
            }
        }
    }

    /// Reads the record at `pos`. Returns `Some(1)` for a record to yield (opcode in `rec[0]`,
    /// body from `rec[1..]`), `None` when the state changed instead (a chunk to iterate,
    /// damage, the end).
    fn top_level(&mut self) -> Result<Option<usize>, SalvageError> {
        if self.pos >= self.data_end {
            self.finish();
            return Ok(None);
        }
        let at = self.pos;
        let mut head = [0u8; FRAMING as usize];
        let got = self.read_at(at, &mut head)?;
        if got < head.len() || at + FRAMING > self.data_end {
            self.damaged(at, "a record cut off by the end of the file".into())?;
            return Ok(None);
        }
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
        let room = self.data_end - at - FRAMING;
        let next_chunk = self.next_indexed(at + 1);
        if let Some(ix) = self.indexed_at(at) {
            let ix_len = ix.len;
            if opcode != op::CHUNK || len.checked_add(FRAMING) != Some(ix_len) {
                let why = format!(
                    "the indexed chunk's record is damaged (opcode {opcode:#04x}, length {len})"
                );
                self.damaged(at, why)?;
                return Ok(None);
            }
        }
        if opcode == op::CHUNK {
            match self.read_chunk(at, len)? {
                Ok(ChunkRecords {
                    at: records_at,
                    end,
                    unpacked,
                }) => {
                    if self.is_duplicate() {
                        self.report.duplicate_chunks += 1;
                        tracing::warn!(
                            offset = at,
                            "a chunk identical to one just read (a block written twice): skipped"
                        );
                        self.pos = at + FRAMING + len;
                        self.trusted = self.pos;
                        return Ok(None);
                    }
                    self.close_open();
                    self.report.chunks_intact += 1;
                    self.chunked = true;
                    self.pos = at + FRAMING + len;
                    self.trusted = self.pos;
                    self.state = State::InChunk {
                        at: records_at,
                        end,
                        unpacked,
                    };
                }
                Err(why) => self.damaged(at, why)?,
            }
            return Ok(None);
        }
        let known = (op::HEADER..=op::DATA_END).contains(&opcode) || opcode >= 0x80;
        let limit = match opcode {
            op::ATTACHMENT | op::METADATA => MAX_ATTACHMENT,
            _ => MAX_SMALL_RECORD,
        };
        let end = at.saturating_add(FRAMING).saturating_add(len);
        let why = if !known {
            Some(format!("not a record (opcode {opcode:#04x})"))
        } else if len > room || len > limit {
            Some(format!(
                "a record (opcode {opcode:#04x}) longer than the file allows ({len} bytes)"
            ))
        } else if next_chunk.is_some_and(|c| end > c) {
            Some(format!(
                "a record (opcode {opcode:#04x}) overlapping the next indexed chunk"
            ))
        } else if self.chunked && matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            Some(format!(
                "a record (opcode {opcode:#04x}) outside any chunk in a chunked file"
            ))
        } else if opcode == op::FOOTER || (opcode == op::HEADER && at != 8) {
            Some(format!("a record (opcode {opcode:#04x}) out of place"))
        } else {
            None
        };
        if let Some(why) = why {
            self.damaged(at, why)?;
            return Ok(None);
        }
        self.rec.clear();
        self.rec.push(opcode);
        self.read_body(at + FRAMING, len)?;
        if let Err(e) = mcap::parse_record(opcode, &self.rec[1..]) {
            self.damaged(
                at,
                format!("a record (opcode {opcode:#04x}) that does not parse: {e}"),
            )?;
            return Ok(None);
        }
        self.pos = end;
        match opcode {
            op::DATA_END => {
                self.finish();
                Ok(None)
            }
            op::MESSAGE_INDEX => {
                self.count_into_open();
                Ok(None)
            }
            op::CHUNK_INDEX
            | op::ATTACHMENT_INDEX
            | op::STATISTICS
            | op::METADATA_INDEX
            | op::SUMMARY_OFFSET => Ok(None),
            _ => {
                if opcode != op::HEADER {
                    self.close_open();
                }
                Ok(Some(1))
            }
        }
    }

    /// Reads and checks the chunk record at `at` (body length `len`) into `rec` (its records
    /// into `unpacked` when compressed): where its records are, or why it is damaged.
    fn read_chunk(
        &mut self,
        at: u64,
        len: u64,
    ) -> Result<Result<ChunkRecords, String>, SalvageError> {
        let room = self.data_end.saturating_sub(at + FRAMING);
        if len > room {
            return Ok(Err(format!(
                "a chunk longer than the file allows ({len} bytes)"
            )));
        }
        let mut head = [0u8; (CHUNK_FIXED + MAX_COMPRESSION_NAME) as usize];
        let want = (len.min(head.len() as u64)) as usize;
        let got = self.read_at(at + FRAMING, &mut head[..want])?;
        if let Err(why) = chunk_lengths_agree(len, &head[..got]) {
            return Ok(Err(why));
        }
        self.rec.clear();
        self.rec.push(op::CHUNK);
        self.read_body(at + FRAMING, len)?;
        Ok(check_chunk(at, &self.rec, &mut self.unpacked))
    }

    /// Reads `len` bytes at `at` onto the end of `rec` (they are in the file: checked).
    fn read_body(&mut self, at: u64, len: u64) -> Result<(), SalvageError> {
        self.seek(at)?;
        self.rec.reserve(len as usize);
        let n = (&mut self.src).take(len).read_to_end(&mut self.rec)?;
        self.src_pos += n as u64;
        if (n as u64) < len {
            return Err(SalvageError::Io(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!("the file shrank while being read (at byte {at})"),
            )));
        }
        Ok(())
    }

    /// Whether the chunk just read (in `rec`) equals one of the last few; remembers it.
    fn is_duplicate(&mut self) -> bool {
        let Ok(Record::Chunk { header, .. }) = mcap::parse_record(op::CHUNK, &self.rec[1..]) else {
            return false;
        };
        let key = ChunkKey {
            start: header.message_start_time,
            end: header.message_end_time,
            crc: header.uncompressed_crc,
            size: header.uncompressed_size,
        };
        // Only a chunk with messages and a CRC can be told apart from a legitimate repeat.
        if header.uncompressed_crc == 0 || header.message_end_time == 0 {
            return false;
        }
        if self.recent.contains(&Some(key)) {
            return true;
        }
        self.recent[self.recent_next] = Some(key);
        self.recent_next = (self.recent_next + 1) % RECENT_CHUNKS;
        false
    }

    /// Skips the damaged record at `at` and finds where reading resumes.
    fn damaged(&mut self, at: u64, reason: String) -> Result<(), SalvageError> {
        let (resume, held) = if !self.index.is_empty() {
            self.resume_by_index(at)?
        } else {
            self.resume_by_scan(at)?
        };
        if resume < at {
            // A valid chunk lies before the damaged record: it was read past (a damaged length
            // that still parsed). Read again from it.
            tracing::debug!(at, resume, "resynchronising back to a chunk read past");
            self.pos = resume;
            return Ok(());
        }
        let cut_short = resume >= self.data_end && !self.report.complete;
        match &mut self.open {
            Some(open) if at <= open.offset + open.len => {
                open.len = resume.max(open.offset + open.len) - open.offset;
                open.cut_short |= cut_short;
                match (&mut open.held, held) {
                    (Some(a), Some(b)) => {
                        for (ch, n) in b {
                            *a.entry(ch).or_default() += n;
                        }
                    }
                    (a, _) => *a = None,
                }
            }
            _ => {
                self.close_open();
                self.open = Some(Damage {
                    offset: at,
                    len: resume - at,
                    reason,
                    held,
                    cut_short,
                });
            }
        }
        self.pos = resume;
        Ok(())
    }

    /// With an intact summary: resume after the damaged chunk (its message indexes follow), or
    /// at the next indexed chunk; the messages held come from the index.
    fn resume_by_index(&mut self, at: u64) -> Result<(u64, Option<Held>), SalvageError> {
        if let Some(ix) = self.indexed_at(at).cloned() {
            let held = self.count_indexed(&ix)?;
            return Ok(((at + ix.len).max(at + 1), held));
        }
        let resume = self.next_indexed(at + 1).unwrap_or(self.data_end);
        Ok((resume, Some(BTreeMap::new())))
    }

    /// Messages per channel of an indexed chunk, from its message index records.
    fn count_indexed(&mut self, ix: &Indexed) -> Result<Option<Held>, SalvageError> {
        let mut held = BTreeMap::new();
        for (&channel, &offset) in &ix.message_indexes {
            let mut head = [0u8; FRAMING as usize];
            if offset + FRAMING > self.data_end || self.read_at(offset, &mut head)? < head.len() {
                return Ok(None);
            }
            let len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
            if head[0] != op::MESSAGE_INDEX || len > self.data_end - offset - FRAMING {
                return Ok(None);
            }
            let mut body = vec![0u8; len as usize];
            if self.read_at(offset + FRAMING, &mut body)? < body.len() {
                return Ok(None);
            }
            match mcap::parse_record(op::MESSAGE_INDEX, &body) {
                Ok(Record::MessageIndex(m)) if m.channel_id == channel => {
                    held.insert(channel, m.records.len() as u64);
                }
                _ => return Ok(None),
            }
        }
        Ok(Some(held))
    }

    /// Without an index: a damaged chunk whose lengths agree is skipped whole (its message
    /// indexes follow and tell what it held); anything else is skipped up to the next valid
    /// chunk, looked for from the end of the last intact one.
    fn resume_by_scan(&mut self, at: u64) -> Result<(u64, Option<Held>), SalvageError> {
        let mut head = [0u8; (FRAMING + CHUNK_FIXED + MAX_COMPRESSION_NAME) as usize];
        let got = self.read_at(at, &mut head)?;
        let is_chunk = got >= FRAMING as usize && head[0] == op::CHUNK;
        self.report.chunks_damaged += u64::from(is_chunk);
        if is_chunk {
            let len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
            if len <= self.data_end - at - FRAMING
                && chunk_lengths_agree(len, &head[FRAMING as usize..got]).is_ok()
            {
                return Ok((at + FRAMING + len, Some(BTreeMap::new())));
            }
        }
        // From the end of the last intact chunk, in case a record that parsed had a damaged
        // length and hid a chunk; but only once from there, so that reading always advances.
        let from = if self.rescanned_from == Some(self.trusted) {
            at
        } else {
            self.rescanned_from = Some(self.trusted);
            self.trusted.min(at)
        };
        let resume = self.scan_for_chunk(from, at)?;
        let resume = if resume == at { at + 1 } else { resume };
        Ok((resume.min(self.data_end), None))
    }

    /// The offset of the first valid chunk at or after `from` that is not `skip`, or the end of
    /// the data.
    fn scan_for_chunk(&mut self, from: u64, skip: u64) -> Result<u64, SalvageError> {
        let header_max = (FRAMING + CHUNK_FIXED + MAX_COMPRESSION_NAME) as usize;
        let mut base = from;
        while base < self.data_end {
            let want = (SCAN_WINDOW + header_max).min((self.data_end - base) as usize);
            let mut window = std::mem::take(&mut self.scan);
            window.resize(want, 0);
            let got = self.read_at(base, &mut window)?;
            window.truncate(got);
            let last_window = base + got as u64 >= self.data_end;
            let mut found = None;
            for i in 0..got.min(SCAN_WINDOW) {
                if window[i] != op::CHUNK || base + i as u64 == skip {
                    continue;
                }
                let head = &window[i..(i + header_max).min(got)];
                if head.len() < FRAMING as usize {
                    continue;
                }
                let at = base + i as u64;
                let len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
                if len > self.data_end - at - FRAMING
                    || chunk_lengths_agree(len, &head[FRAMING as usize..]).is_err()
                {
                    continue;
                }
                if let Ok(Ok(_)) = self.read_chunk(at, len) {
                    found = Some(at);
                    break;
                }
            }
            self.scan = window;
            if let Some(at) = found {
                return Ok(at);
            }
            if last_window || got == 0 {
                break;
            }
            base += SCAN_WINDOW as u64;
        }
        Ok(self.data_end)
    }

    /// Adds the message index record in `rec` to the open damage region's count.
    fn count_into_open(&mut self) {
        if !self.index.is_empty() {
            return; // the index already counted what the region held
        }
        let Some(open) = &mut self.open else { return };
        let Some(held) = &mut open.held else { return };
        if let Ok(Record::MessageIndex(m)) = mcap::parse_record(op::MESSAGE_INDEX, &self.rec[1..]) {
            *held.entry(m.channel_id).or_default() += m.records.len() as u64;
        }
        open.len = self.pos - open.offset;
    }

    /// Reports the open damage region (yielded before anything else).
    fn close_open(&mut self) {
        if let Some(d) = self.open.take() {
            self.report.damage.push(d);
            self.emit = Some(self.report.damage.len() - 1);
        }
    }

    fn finish(&mut self) {
        self.close_open();
        if let Some(n) = self.report.indexed_chunks {
            self.report.chunks_damaged = n.saturating_sub(self.report.chunks_intact);
        }
        self.state = State::Done;
    }

    fn indexed_at(&self, at: u64) -> Option<&Indexed> {
        self.index
            .binary_search_by_key(&at, |c| c.start)
            .ok()
            .map(|i| &self.index[i])
    }

    /// The first indexed chunk starting at or after `at`.
    fn next_indexed(&self, at: u64) -> Option<u64> {
        let i = self.index.partition_point(|c| c.start < at);
        self.index.get(i).map(|c| c.start)
    }

    fn seek(&mut self, at: u64) -> std::io::Result<()> {
        if at == self.src_pos {
            return Ok(());
        }
        if self.src_pos != u64::MAX && at.abs_diff(self.src_pos) < 1 << 20 {
            // Within the buffer when possible (a chunk's header is read, then its body).
            self.src.seek_relative(at as i64 - self.src_pos as i64)?;
        } else {
            self.src.seek(SeekFrom::Start(at))?;
        }
        self.src_pos = at;
        Ok(())
    }

    /// Reads up to `buf.len()` bytes at `at`; the count (short at the end of the file).
    fn read_at(&mut self, at: u64, buf: &mut [u8]) -> std::io::Result<usize> {
        self.seek(at)?;
        let mut n = 0;
        while n < buf.len() {
            match self.src.read(&mut buf[n..]) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    self.src_pos = u64::MAX;
                    return Err(e);
                }
            }
        }
        self.src_pos += n as u64;
        Ok(n)
    }

    /// Reads and checks the summary section; fills the index and the definitions.
    fn read_summary(
        &mut self,
        start: u64,
        crc: u32,
        footer_at: u64,
        tail: &[u8],
    ) -> Result<(), String> {
        if start < 8 || start > footer_at {
            return Err(format!(
                "the footer's summary offset {start} is outside the file"
            ));
        }
        let len = footer_at - start;
        if len > MAX_ATTACHMENT {
            return Err(format!("a summary of {len} bytes"));
        }
        let mut buf = vec![0u8; len as usize];
        match self.read_at(start, &mut buf) {
            Ok(n) if n == buf.len() => {}
            Ok(_) => return Err("the summary is cut off".into()),
            Err(e) => return Err(e.to_string()),
        }
        let mut failed = None;
        if crc != 0 {
            let mut h = crc32fast::Hasher::new();
            h.update(&buf);
            h.update(&tail[..25]);
            let calculated = h.finalize();
            if calculated != crc {
                failed = Some(format!(
                    "its CRC does not match (saved {crc:#010x}, calculated {calculated:#010x})"
                ));
            }
        }
        // Even a damaged summary lends its schemas and channels (those that parse): the chunk
        // that defined them may be damaged too. Its chunk index is used only when intact.
        let mut at = 0;
        while at < buf.len() {
            let Some((opcode, body_at, next)) = frame(&buf, at) else {
                return Err(failed
                    .unwrap_or_else(|| format!("a record cut off at byte {}", start + at as u64)));
            };
            let record = match mcap::parse_record(opcode, &buf[body_at..next]) {
                Ok(r) => r,
                Err(e) => {
                    return Err(failed
                        .unwrap_or_else(|| format!("record at byte {}: {e}", start + at as u64)))
                }
            };
            match record {
                Record::ChunkIndex(c) => {
                    let end = c.chunk_start_offset.checked_add(c.chunk_length);
                    if c.chunk_start_offset < 8 || end.is_none_or(|e| e > start) {
                        failed.get_or_insert_with(|| {
                            format!(
                                "a chunk index entry outside the data section (offset {})",
                                c.chunk_start_offset
                            )
                        });
                    }
                    self.index.push(Indexed {
                        start: c.chunk_start_offset,
                        len: c.chunk_length,
                        message_indexes: c.message_index_offsets,
                    });
                }
                Record::Schema { header, data } => self
                    .definitions
                    .push(Definition::Schema(header, data.into_owned())),
                Record::Channel(c) => self.definitions.push(Definition::Channel(c)),
                _ => {}
            }
            at = next;
        }
        if let Some(why) = failed {
            return Err(why);
        }
        self.index.sort_by_key(|c| c.start);
        if self
            .index
            .windows(2)
            .any(|w| w[0].start + w[0].len > w[1].start)
        {
            return Err("overlapping chunk index entries".into());
        }
        Ok(())
    }
}

/// The record at `buf[at..]`: (opcode, body start, end), or `None` if its length runs past
/// the buffer.
fn frame(buf: &[u8], at: usize) -> Option<(u8, usize, usize)> {
    let head = buf.get(at..at.checked_add(FRAMING as usize)?)?;
    let len = u64::from_le_bytes(head[1..9].try_into().ok()?);
    let body_at = at + FRAMING as usize;
    let end = body_at.checked_add(usize::try_from(len).ok()?)?;
    (end <= buf.len()).then_some((head[0], body_at, end))
}

/// Whether a chunk body of `len` bytes beginning with `head` has a header whose lengths
/// agree with it: the boundary test for the next chunk (the rest is checked by parsing).
fn chunk_lengths_agree(len: u64, head: &[u8]) -> Result<(), String> {
    let u64_at = |i: usize| {
        head.get(i..i + 8)
            .map(|b| u64::from_le_bytes(b.try_into().expect("8")))
    };
    let u32_at = |i: usize| {
        head.get(i..i + 4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4")))
    };
    let (Some(start), Some(end), Some(size), Some(name_len)) =
        (u64_at(0), u64_at(8), u64_at(16), u32_at(28))
    else {
        return Err("a chunk too short for its header".into());
    };
    let name_len = u64::from(name_len);
    if name_len > MAX_COMPRESSION_NAME {
        return Err("a chunk header with a damaged compression name".into());
    }
    let name = &head[32..(32 + name_len as usize).min(head.len())];
    if !matches!(name, b"" | b"zstd" | b"lz4") {
        return Err("a chunk header with an unknown compression".into());
    }
    let Some(compressed) = u64_at(32 + name_len as usize) else {
        return Err("a chunk too short for its header".into());
    };
    if CHUNK_FIXED
        .checked_add(name_len)
        .and_then(|h| h.checked_add(compressed))
        != Some(len)
    {
        return Err(format!(
            "a chunk whose lengths disagree (record {len}, records {compressed})"
        ));
    }
    if name.is_empty() && size != compressed {
        return Err("an uncompressed chunk whose sizes disagree".into());
    }
    if start > end {
        return Err("a chunk whose time range is reversed".into());
    }
    Ok(())
}

/// Where a checked chunk's records are: `rec[at..end]`, or `unpacked[at..end]` when the chunk
/// was compressed.
struct ChunkRecords {
    at: usize,
    end: usize,
    unpacked: bool,
}

/// Checks a chunk record (`rec`: opcode, then body): parses, decompresses (into `unpacked`),
/// CRC, every record inside parses and the time range matches the messages.
fn check_chunk(at: u64, rec: &[u8], unpacked: &mut Vec<u8>) -> Result<ChunkRecords, String> {
    let body = &rec[1..];
    let (header, data) = match mcap::parse_record(op::CHUNK, body) {
        Ok(Record::Chunk { header, data }) => (header, data),
        Ok(_) => unreachable!("parsed as a chunk"),
        Err(e) => return Err(format!("a chunk that does not parse: {e}")),
    };
    let compressed = !header.compression.is_empty();
    let (records, found) = if compressed {
        decompress(
            &header.compression,
            &data,
            header.uncompressed_size,
            unpacked,
        )?;
        let n = unpacked.len();
        (
            &unpacked[..],
            ChunkRecords {
                at: 0,
                end: n,
                unpacked: true,
            },
        )
    } else {
        let records_at = 1 + body.len() - data.len();
        (
            &rec[records_at..],
            ChunkRecords {
                at: records_at,
                end: rec.len(),
                unpacked: false,
            },
        )
    };
    if header.uncompressed_crc != 0 {
        let calculated = crc32fast::hash(records);
        if calculated != header.uncompressed_crc {
            return Err(format!(
                "a chunk whose CRC does not match (saved {:#010x}, calculated {calculated:#010x})",
                header.uncompressed_crc
            ));
        }
    }
    // Positions in messages: file offsets for stored records, offsets into the decompressed
    // records for compressed ones.
    let place = |i: usize| {
        if compressed {
            format!("byte {i} of its decompressed records")
        } else {
            format!("byte {}", at + (found.at + i) as u64 - 1)
        }
    };
    let mut bounds: Option<(u64, u64)> = None;
    let mut i = 0;
    while i < records.len() {
        let Some((opcode, body_at, next)) = frame(records, i) else {
            return Err(format!(
                "a chunk whose record at {} runs past its end",
                place(i)
            ));
        };
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            return Err(format!("a chunk holding a record of opcode {opcode:#04x}"));
        }
        match mcap::parse_record(opcode, &records[body_at..next]) {
            Ok(Record::Message { header, .. }) => {
                let t = header.log_time;
                bounds = Some(bounds.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
            }
            Ok(_) => {}
            Err(e) => return Err(format!("a chunk holding a record that does not parse: {e}")),
        }
        i = next;
    }
    if let Some((first, last)) = bounds {
        if (first, last) != (header.message_start_time, header.message_end_time) {
            return Err("a chunk whose time range does not match its messages".into());
        }
    }
    Ok(found)
}

/// Decompresses a chunk's records (`zstd` or `lz4` frames) into `out`, which must come to
/// exactly `size` bytes.
fn decompress(compression: &str, data: &[u8], size: u64, out: &mut Vec<u8>) -> Result<(), String> {
    if size > MAX_UNCOMPRESSED_CHUNK {
        return Err(format!(
            "a {compression} chunk that claims {size} bytes uncompressed"
        ));
    }
    out.clear();
    out.reserve(size as usize);
    // One byte more than stated tells a chunk that decompresses to more.
    let read = match compression {
        "zstd" => ruzstd::decoding::StreamingDecoder::new(data)
            .map_err(|e| e.to_string())
            .and_then(|d| d.take(size + 1).read_to_end(out).map_err(|e| e.to_string())),
        "lz4" => lz4_flex::frame::FrameDecoder::new(data)
            .take(size + 1)
            .read_to_end(out)
            .map_err(|e| e.to_string()),
        other => return Err(format!("a chunk with an unknown compression `{other}`")),
    };
    match read {
        Ok(n) if n as u64 == size => Ok(()),
        Ok(n) => Err(format!(
            "a {compression} chunk that decompresses to {}{n} bytes, not the {size} it states",
            if n as u64 > size { "more than " } else { "" }
        )),
        Err(e) => Err(format!(
            "a {compression} chunk that does not decompress: {e}"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_rejects_lengths_past_the_buffer() {
        let mut b = vec![5u8];
        b.extend_from_slice(&3u64.to_le_bytes());
        b.extend_from_slice(&[1, 2, 3]);
        assert_eq!(frame(&b, 0), Some((5, 9, 12)));
        assert_eq!(frame(&b[..11], 0), None);
        let mut huge = vec![5u8];
        huge.extend_from_slice(&u64::MAX.to_le_bytes());
        assert_eq!(frame(&huge, 0), None);
    }

    #[test]
    fn not_mcap_is_an_error() {
        let e = Salvage::new(std::io::Cursor::new(b"hello, world".to_vec()))
            .err()
            .unwrap();
        assert!(matches!(e, SalvageError::NotMcap), "{e}");
    }
}
