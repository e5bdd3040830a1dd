//! Fuzz the replay of foreign MCAP files: any bytes either refuse to open with an error or
//! replay (skipping damage) to the end; never a panic, a hang or a runaway allocation. Covers
//! the salvage reader (`omnirow recording check`/`repair`), the image message decoders (ROS 2
//! CDR, Foxglove CDR/protobuf/JSON) and the recorded ground truth. Seeds: recordings that
//! scripts/fuzz.sh makes with `omnirow record`.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::record::salvage::Salvage;
use omnirow::source::mcap_replay::{McapReplay, McapReplayOptions};
use omnirow::source::{Poll, Rate, Source};
use std::time::Duration;

/// Removes the input's temporary file however the replay ends (a crash keeps it: libFuzzer
/// writes its own artefact).
struct RemoveOnDrop<'a>(&'a std::path::Path);

impl Drop for RemoveOnDrop<'_> {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(self.0);
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(mut r) = Salvage::new(std::io::Cursor::new(data)) {
        while let Ok(Some(_)) = r.next_event() {}
    }
    let path = std::env::temp_dir().join(format!("omnirow-fuzz-{}.mcap", std::process::id()));
    std::fs::write(&path, data).expect("temporary file");
    let _remove = RemoveOnDrop(&path);
    let Ok(mut src) = McapReplay::open(McapReplayOptions {
        path: path.clone(),
        rate: Rate::Max,
        looping: false,
        topic: None,
    }) else {
        return;
    };
    // Every frame is at least one message of at least a few bytes: the input bounds them.
    for _ in 0..=data.len() {
        match src.poll(Duration::ZERO) {
            Ok(Poll::End) | Err(_) => return,
            Ok(Poll::Frame(f)) => assert!(f.view().is_ok(), "a replayed frame matches its size"),
            Ok(Poll::Idle) => {}
        }
    }
    panic!("replay of {} bytes did not end", data.len());
});
