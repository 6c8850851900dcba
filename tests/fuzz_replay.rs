//! Replays the fuzzers' corpora (`fuzz/corpus/<target>/`) and the kept findings
//! (`fuzz/artifacts/<target>/`: inputs that once crashed, hung or exhausted memory) through the
//! same entry points as the fuzz targets, on the stable toolchain: none may panic. Errors are
//! the expected answer to most of these inputs.

use crate::common::root;
use std::path::PathBuf;
use std::time::Instant;

fn inputs(target: &str) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for kind in ["corpus", "artifacts"] {
        let dir = root().join("fuzz").join(kind).join(target);
        if let Ok(rd) = std::fs::read_dir(&dir) {
            files.extend(rd.flatten().map(|e| e.path()).filter(|p| p.is_file()));
        }
    }
    files.sort();
    files
}

fn replay(target: &str, run: impl Fn(&[u8]) + std::panic::RefUnwindSafe) {
    let files = inputs(target);
    assert!(
        files.len() >= 5,
        "{target}: the corpus is missing ({} files)",
        files.len()
    );
    let t = Instant::now();
    let mut failed = Vec::new();
    for f in &files {
        let data = std::fs::read(f).unwrap();
        if std::panic::catch_unwind(|| run(&data)).is_err() {
            failed.push(f.display().to_string());
        }
    }
    eprintln!(
        "{target}: {} inputs replayed in {:.2} s",
        files.len(),
        t.elapsed().as_secs_f64()
    );
    assert!(failed.is_empty(), "{target}: panics on {failed:#?}");
}

#[test]
fn scene_parser_corpus_replays_without_panics() {
    let dir = matfit::fuzzing::fixtures_dir();
    replay("scene_parser", |d| matfit::fuzzing::scene_parser(d, &dir));
}

#[test]
fn photo_loader_corpus_replays_without_panics() {
    replay("photo_loader", matfit::fuzzing::photo_loader);
}

#[test]
fn mesh_loader_corpus_replays_without_panics() {
    replay("mesh_loader", matfit::fuzzing::mesh_loader);
}
