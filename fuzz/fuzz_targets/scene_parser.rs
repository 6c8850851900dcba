//! Scene files: arbitrary bytes → UTF-8 → `parse_scene` (and back: `scene_to_toml`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    matfit::fuzzing::scene_parser(data, &matfit::fuzzing::fixtures_dir());
});
