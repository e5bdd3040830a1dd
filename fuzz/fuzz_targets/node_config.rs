//! Fuzz the node's configuration parser (`omnirow run --config`, `omnirow config check`): any
//! text is a configuration or an error naming the key; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::config::Config;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = Config::parse(text, "fuzz.toml");
    }
});
