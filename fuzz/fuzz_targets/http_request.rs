//! Fuzz the HTTP endpoint's request reader: any bytes from a client give a method and path or
//! an I/O error; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::publish::http::read_request;

fuzz_target!(|data: &[u8]| {
    let mut reader = std::io::BufReader::new(data);
    if let Ok((method, path)) = read_request(&mut reader) {
        assert!(!method.contains(char::is_whitespace) && !path.contains('?'));
    }
});
