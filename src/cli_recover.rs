//! The `recover` command's work: run the engine with a JSON-lines log, then write the outputs.

use crate::fit::{recover, RecoverOptions, Recovery};
use crate::photo::{Photo, UsableMask};
use crate::scene::Scene;
use std::io::Write;
use std::path::Path;

/// Recovers `scene`'s materials from `photo`, writing log.jsonl as it goes and every other
/// output at the end into `out` (which must exist).
pub fn run_recover(
    scene: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    opts: &RecoverOptions,
    out: &Path,
) -> Result<Recovery, String> {
    let log_path = out.join("log.jsonl");
    let f = std::fs::File::create(&log_path)
        .map_err(|e| format!("cannot write {}: {e}", log_path.display()))?;
    let mut log = std::io::BufWriter::new(f);
    let mut log_err = None;
    let rec = recover(scene, photo, mask, opts, |line| {
        let s = serde_json::to_string(line).expect("log line serialises");
        if let Err(e) = writeln!(log, "{s}").and_then(|_| log.flush()) {
            log_err.get_or_insert(e);
        }
    });
    if let Some(e) = log_err {
        return Err(format!("cannot write {}: {e}", log_path.display()));
    }
    crate::report::write_outputs(out, &rec, photo)?;
    Ok(rec)
}
