//! Photos: arbitrary bytes → the decoding and checks `recover` applies (EXR, HDR, PFM, PNG, JPEG).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    matfit::fuzzing::photo_loader(data);
});
