//! Checks the commands make before their long work that are the command line's own: the
//! output folder (the others are the library's, `matfit::__internal::api::checks`), and what
//! Ctrl-C says.

use anyhow::{bail, Result};
use matfit::api::checks::OUTPUT_MARKS;
use std::path::Path;

/// Refuses to write into a folder that holds other things than a matfit output, unless
/// `force`; says when a previous matfit output is overwritten.
pub fn output_folder(dir: &Path, force: bool) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(()); // absent (created later) or not a folder (reported when it is created)
    };
    let mut names: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with(".matfit-probe-"))
        .collect();
    names.sort();
    if names.is_empty() {
        return Ok(());
    }
    if names.iter().any(|n| OUTPUT_MARKS.contains(&n.as_str())) {
        eprintln!("note: writing over the matfit output in {}", dir.display());
        return Ok(());
    }
    if force {
        eprintln!(
            "note: writing into {}, which holds other files (--force)",
            dir.display()
        );
        return Ok(());
    }
    bail!(
        "{} is not empty ({} entr{}, e.g. '{}') and is not a matfit output: refusing to write \
         there (choose another folder, or --force to write into it anyway)",
        dir.display(),
        names.len(),
        if names.len() == 1 { "y" } else { "ies" },
        names[0]
    )
}

/// On Ctrl-C during `recover`: say how to continue from the last checkpoint, then stop.
pub fn on_interrupt_say_resume(resume_cmd: String) {
    let r = ctrlc::set_handler(move || {
        eprintln!(
            "\ninterrupted: the last finished global iteration is saved; continue with\n  {resume_cmd}"
        );
        std::process::exit(130);
    });
    if let Err(e) = r {
        tracing::debug!("no Ctrl-C handler: {e}");
    }
}
