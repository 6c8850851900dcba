//! Mesh files: a format byte + arbitrary bytes → the OBJ, PLY or glTF loader and `validate`.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    matfit::fuzzing::mesh_loader(data);
});
