//! A damaged recording loses exactly the frames whose chunks the damage hit, and no others:
//! random byte flips, zeroed 4 KiB pages, truncation at every chunk boundary and inside every
//! chunk, a missing summary, a duplicated chunk. The expected frames come from the intact
//! file's chunk index (which chunk holds which frame) and a byte comparison of the two files
//! (which chunks were hit); replay goes through `McapReplay`, as the node's does.

use omnirow::camera::IdealLens;
use omnirow::estimate::{Estimate, Status};
use omnirow::frame::{Frame, PixelFormat};
use omnirow::record::salvage::{Event, Salvage, SummaryState};
use omnirow::record::{RecordOptions, Recorder, IMAGE_TOPIC};
use omnirow::source::mcap_replay::{McapReplay, McapReplayOptions};
use omnirow::source::{Poll, Rate, Source};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// splitmix64: fixed seeds, no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn frame(seq: u64) -> Frame {
    let (width, height, format) = if seq % 3 == 0 {
        (40, 30, PixelFormat::Rgb8)
    } else {
        (64, 48, PixelFormat::Mono8)
    };
    let n = (width * height) as usize * format.bytes_per_pixel();
    Frame {
        seq,
        capture_ns: 1_700_000_000_000_000_000 + seq * 66_666_667,
        receive_ns: 1_700_000_000_010_000_000 + seq * 66_666_667,
        width,
        height,
        format,
        data: (0..n).map(|i| (i as u64 * 31 + seq * 7) as u8).collect(),
        truth: None,
    }
}

struct Fixture {
    dir: PathBuf,
    bytes: Vec<u8>,
    /// Per chunk: its byte range and the capture stamps of the frames it holds.
    chunks: Vec<(u64, u64, Vec<u64>)>,
    /// Every frame's capture stamp, in order.
    all: Vec<u64>,
}

/// A 60-frame recording as the node writes it (a frame, then its estimate), and its layout.
fn fixture(name: &str) -> Fixture {
    let dir = std::env::temp_dir().join(format!("omnirow-damage-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut rec = Recorder::new(RecordOptions {
        dir: dir.join("rec"),
        reserve_bytes: 0,
        calibration_toml: Some(IdealLens::Fisheye185.calibration(48, 64).unwrap().to_toml()),
        ..RecordOptions::default()
    })
    .unwrap();
    for i in 0..60 {
        let f = frame(i);
        rec.write_frame(&f).unwrap();
        rec.write_estimate(&Estimate::empty(&f, Status::NoRows))
            .unwrap();
    }
    rec.finish().unwrap();
    let bytes = std::fs::read(&rec.files()[0]).unwrap();
    layout(dir, bytes)
}

/// The same recording rewritten by mcap's own writer with `compression` (as ros2 bag or
/// Foxglove write them), a chunk per frame.
fn compressed_fixture(name: &str, compression: mcap::Compression) -> Fixture {
    let plain = fixture(&format!("{name}-plain"));
    let dir = std::env::temp_dir().join(format!("omnirow-damage-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    let mut w = mcap::WriteOptions::new()
        .compression(Some(compression))
        .chunk_size(Some(1024))
        .create(&mut out)
        .unwrap();
    for m in mcap::MessageStream::new(&plain.bytes).unwrap() {
        w.write(&m.unwrap()).unwrap();
    }
    w.finish().unwrap();
    drop(w);
    layout(dir, out.into_inner())
}

/// Which chunk holds which frame, from the intact file's summary.
fn layout(dir: PathBuf, bytes: Vec<u8>) -> Fixture {
    let summary = mcap::Summary::read(&bytes).unwrap().expect("summary");
    let mut chunks = Vec::new();
    let mut all = Vec::new();
    for idx in &summary.chunk_indexes {
        let mut stamps = Vec::new();
        for m in summary.stream_chunk(&bytes, idx).unwrap() {
            let m = m.unwrap();
            if m.channel.topic == IMAGE_TOPIC {
                stamps.push(m.publish_time);
            }
        }
        all.extend(&stamps);
        chunks.push((
            idx.chunk_start_offset,
            idx.chunk_start_offset + idx.chunk_length,
            stamps,
        ));
    }
    assert_eq!(all.len(), 60);
    assert!(
        chunks.len() > 60,
        "one chunk per frame, plus the definitions"
    );
    Fixture {
        dir,
        bytes,
        chunks,
        all,
    }
}

impl Fixture {
    /// The frames of every chunk whose bytes in `damaged` differ from the intact file's (or
    /// are missing from it).
    fn expected(&self, damaged: &[u8]) -> Vec<u64> {
        let mut out = Vec::new();
        for (start, end, stamps) in &self.chunks {
            let (s, e) = (*start as usize, *end as usize);
            if e <= damaged.len() && damaged[s..e] == self.bytes[s..e] {
                out.extend(stamps);
            }
        }
        out
    }

    fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// Replays `bytes` and asserts exactly `expected` came back, in order.
    fn check(&self, what: &str, bytes: &[u8], expected: &[u64]) {
        let got = replay(&self.write("damaged.mcap", bytes));
        if got != expected {
            // Keep the case for a look: the file, and what salvage made of it.
            let keep = std::env::temp_dir().join("omnirow-damage-failed.mcap");
            std::fs::write(&keep, bytes).unwrap();
            let mut r = Salvage::new(std::io::Cursor::new(bytes.to_vec())).unwrap();
            while r.next_event().unwrap().is_some() {}
            panic!(
                "{what}: replayed {} frames, expected {} (file kept as {}): {:?}\ngot {got:?}\nexpected {expected:?}",
                got.len(),
                expected.len(),
                keep.display(),
                r.report()
            );
        }
    }
}

impl Drop for Fixture {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Replays `path`: the capture stamps of the frames that came back, each checked against the
/// frame recorded with that stamp (pixels and all).
fn replay(path: &Path) -> Vec<u64> {
    let mut src = McapReplay::open(McapReplayOptions {
        path: path.to_path_buf(),
        rate: Rate::Max,
        looping: false,
        topic: None,
    })
    .unwrap();
    let mut out = Vec::new();
    loop {
        let poll = match src.poll(Duration::from_millis(10)) {
            Ok(p) => p,
            // A file cut or damaged before its channel definitions has no frames to give.
            Err(e) if out.is_empty() && e.to_string().contains("no image channel") => return out,
            Err(e) => panic!("{e}"),
        };
        match poll {
            Poll::Frame(f) => {
                let seq = (f.capture_ns - 1_700_000_000_000_000_000) / 66_666_667;
                let want = frame(seq);
                assert_eq!(
                    (f.capture_ns, f.width, f.height, f.format),
                    (want.capture_ns, want.width, want.height, want.format)
                );
                assert!(f.data == want.data, "frame {seq}: pixels intact");
                out.push(f.capture_ns);
            }
            Poll::Idle => {}
            Poll::End => return out,
        }
    }
}

#[test]
fn intact_recording_replays_every_frame() {
    let fx = fixture("intact");
    fx.check("intact", &fx.bytes, &fx.all);
    let mut r = Salvage::new(std::io::Cursor::new(fx.bytes.clone())).unwrap();
    while r.next_event().unwrap().is_some() {}
    let report = r.report();
    assert!(report.is_clean(), "{report:?}");
    assert_eq!(report.summary, Some(SummaryState::Intact));
    assert_eq!(report.chunks_intact, fx.chunks.len() as u64);
}

/// Recordings compressed with zstd or lz4 replay whole, and damage in them loses exactly
/// the chunks it hit, as in a stored one.
#[test]
fn compressed_recordings_replay_and_lose_only_damaged_chunks() {
    for (name, compression) in [
        ("zstd", mcap::Compression::Zstd),
        ("lz4", mcap::Compression::Lz4),
    ] {
        let fx = compressed_fixture(name, compression);
        fx.check(name, &fx.bytes, &fx.all);
        let mut r = Salvage::new(std::io::Cursor::new(fx.bytes.clone())).unwrap();
        while r.next_event().unwrap().is_some() {}
        assert!(r.report().is_clean(), "{name}: {:?}", r.report());
        for seed in 0..4 {
            let mut rng = Rng(100 + seed);
            let mut bytes = fx.bytes.clone();
            for _ in 0..6 {
                // Inside the chunks' compressed records, where a decoder meets the damage.
                let (start, end, _) = &fx.chunks[rng.below(fx.chunks.len() as u64) as usize];
                let at = end - 1 - rng.below((end - start) / 2);
                bytes[at as usize] ^= 1 + rng.below(255) as u8;
            }
            let expected = fx.expected(&bytes);
            assert!(
                expected.len() < fx.all.len(),
                "{name} seed {seed}: no frame hit"
            );
            fx.check(&format!("{name}, 6 flips, seed {seed}"), &bytes, &expected);
        }
    }
}

#[test]
fn random_byte_flips_lose_only_the_chunks_they_hit() {
    let fx = fixture("flips");
    let mut lost_any = false;
    // OMNIROW_DAMAGE_SEEDS=N runs N seeds (16 in the default run).
    let seeds = std::env::var("OMNIROW_DAMAGE_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(16u64);
    for seed in 0..seeds {
        let mut rng = Rng(seed);
        let mut bytes = fx.bytes.clone();
        for _ in 0..20 {
            let at = rng.below(bytes.len() as u64) as usize;
            bytes[at] ^= 1 + rng.below(255) as u8;
        }
        let expected = fx.expected(&bytes);
        lost_any |= expected.len() < fx.all.len();
        assert!(
            expected.len() >= 30,
            "seed {seed}: the damage is spread thin"
        );
        fx.check(&format!("20 flips, seed {seed}"), &bytes, &expected);
    }
    assert!(lost_any);
}

#[test]
fn zeroed_pages_lose_only_the_chunks_they_hit() {
    let fx = fixture("pages");
    let pages = fx.bytes.len().div_ceil(4096);
    for page in 0..pages {
        let mut bytes = fx.bytes.clone();
        let end = ((page + 1) * 4096).min(bytes.len());
        bytes[page * 4096..end].fill(0);
        let expected = fx.expected(&bytes);
        fx.check(&format!("page {page} zeroed"), &bytes, &expected);
    }
    // Three pages at once, without the summary's help when one of them hits it.
    let mut rng = Rng(7);
    let rounds = std::env::var("OMNIROW_DAMAGE_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(8u64);
    for round in 0..rounds {
        let mut bytes = fx.bytes.clone();
        for _ in 0..3 {
            let page = rng.below(pages as u64) as usize;
            let end = ((page + 1) * 4096).min(bytes.len());
            bytes[page * 4096..end].fill(0);
        }
        let expected = fx.expected(&bytes);
        fx.check(
            &format!("three pages zeroed, round {round}"),
            &bytes,
            &expected,
        );
    }
}

#[test]
fn truncation_keeps_every_complete_chunk() {
    let fx = fixture("cut");
    let mut cuts: Vec<usize> = Vec::new();
    for (start, end, _) in &fx.chunks {
        let (s, e) = (*start as usize, *end as usize);
        cuts.extend([s, s + 1, s + 9, s + (e - s) / 2, e - 1, e]);
    }
    cuts.extend((9..fx.bytes.len()).step_by(4999));
    for cut in cuts {
        let bytes = &fx.bytes[..cut];
        fx.check(&format!("cut at {cut}"), bytes, &fx.expected(bytes));
    }
}

#[test]
fn missing_summary_and_damage_without_it() {
    let fx = fixture("nosummary");
    let data_end = mcap::read::footer(&fx.bytes).unwrap().summary_start as usize;
    // Cut just before the summary: every frame, no damage, "cut short".
    let bytes = &fx.bytes[..data_end];
    fx.check("no summary", bytes, &fx.all);
    let mut r = Salvage::new(std::io::Cursor::new(bytes.to_vec())).unwrap();
    while r.next_event().unwrap().is_some() {}
    assert_eq!(r.report().summary, Some(SummaryState::Missing));
    assert!(!r.report().complete);
    assert!(r.report().damage.is_empty(), "{:?}", r.report().damage);
    // And flips on top: the chunks are found by scanning.
    let seeds = std::env::var("OMNIROW_DAMAGE_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10u64);
    for seed in 100..100 + seeds {
        let mut rng = Rng(seed);
        let mut bytes = fx.bytes[..data_end].to_vec();
        for _ in 0..10 {
            let at = rng.below(bytes.len() as u64) as usize;
            bytes[at] ^= 1 + rng.below(255) as u8;
        }
        fx.check(
            &format!("no summary, 10 flips, seed {seed}"),
            &bytes,
            &fx.expected(&bytes),
        );
    }
}

#[test]
fn a_duplicated_chunk_replays_once() {
    let fx = fixture("dup");
    for k in [1, 2, 30, fx.chunks.len() - 1] {
        let (s, e, _) = &fx.chunks[k];
        let (s, e) = (*s as usize, *e as usize);
        let mut bytes = fx.bytes[..e].to_vec();
        bytes.extend_from_slice(&fx.bytes[s..e]);
        bytes.extend_from_slice(&fx.bytes[e..]);
        fx.check(&format!("chunk {k} written twice"), &bytes, &fx.all);
        let mut r = Salvage::new(std::io::Cursor::new(bytes)).unwrap();
        while r.next_event().unwrap().is_some() {}
        assert_eq!(r.report().duplicate_chunks, 1, "chunk {k}");
    }
}

#[test]
fn each_damaged_region_is_reported_once_with_the_frames_it_held() {
    let fx = fixture("report");
    let (s, e, stamps) = fx.chunks[10].clone();
    assert_eq!(stamps.len(), 1);
    for with_summary in [true, false] {
        let mut bytes = fx.bytes.clone();
        bytes[(s + e) as usize / 2] ^= 0x55;
        if !with_summary {
            let data_end = mcap::read::footer(&fx.bytes).unwrap().summary_start as usize;
            bytes.truncate(data_end);
        }
        let mut r = Salvage::new(std::io::Cursor::new(bytes)).unwrap();
        let mut image_channel = None;
        let mut regions = Vec::new();
        while let Some(ev) = r.next_event().unwrap() {
            match ev {
                Event::Record(mcap::records::Record::Channel(c)) if c.topic == IMAGE_TOPIC => {
                    image_channel = Some(c.id)
                }
                Event::Damage(d) => regions.push(d.clone()),
                _ => {}
            }
        }
        assert_eq!(regions.len(), 1, "summary {with_summary}: {regions:?}");
        let d = &regions[0];
        assert_eq!(d.offset, s, "the region starts at the damaged chunk");
        assert!(d.len >= e - s, "and covers it");
        assert_eq!(d.held_on(image_channel.unwrap()), Some(1), "{d:?}");
        assert!(d.reason.contains("CRC"), "{}", d.reason);
        assert_eq!(r.report().chunks_damaged, 1);
        assert_eq!(r.report().damage.len(), 1);
    }
}

/// Inputs the fuzzer found (tests/data/fuzz/): each replays to its end. The first was a
/// duplicated chunk followed by damage: the scan for the next chunk went back to the
/// duplicate, skipped it, met the damage again, and never ended.
#[test]
fn fuzzer_findings_replay_to_the_end() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let path = e.unwrap().path();
        if path.extension().and_then(|x| x.to_str()) != Some("mcap") {
            continue; // the other targets' findings
        }
        let mut r = Salvage::new(std::io::Cursor::new(std::fs::read(&path).unwrap())).unwrap();
        let mut events = 0;
        while r.next_event().unwrap().is_some() {
            events += 1;
            assert!(events < 100_000, "{}: no end", path.display());
        }
        if let Ok(mut src) = McapReplay::open(McapReplayOptions {
            path: path.clone(),
            rate: Rate::Max,
            looping: false,
            topic: None,
        }) {
            for _ in 0..100_000 {
                match src.poll(Duration::ZERO) {
                    Ok(Poll::End) | Err(_) => break,
                    _ => {}
                }
            }
            assert_eq!(src.state(), omnirow::source::SourceState::Ended);
        }
        n += 1;
    }
    assert!(n >= 1);
}

#[test]
fn a_duplicate_then_damage_without_a_summary_ends() {
    let fx = fixture("dup-damage");
    let (s, e, _) = fx.chunks[5];
    let (s, e) = (s as usize, e as usize);
    let data_end = mcap::read::footer(&fx.bytes).unwrap().summary_start as usize;
    let mut bytes = fx.bytes[..e].to_vec();
    bytes.extend_from_slice(&fx.bytes[s..e]);
    bytes.extend_from_slice(&[0u8; 64]);
    bytes.extend_from_slice(&fx.bytes[e..data_end]);
    fx.check("a duplicate, then zeros, no summary", &bytes, &fx.all);
}
