//! Atomic output: write to a temporary file in the destination folder, flush it to disk, then
//! rename over the destination, so a reader (or a resumed run) never sees half a file.

use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// Calls `fill` on a temporary file next to `path`, then renames it to `path`.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".matfit-").suffix(".tmp");
    // The permissions of a file created plainly (0o666 less the umask), not tempfile's 0o600:
    // outputs are meant to be read, shared and served.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let mut tmp = builder.tempfile_in(dir)?;
    {
        let mut w = std::io::BufWriter::new(tmp.as_file());
        fill(&mut w)?;
        w.flush()?;
    }
    tmp.as_file_mut().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Creates the output folder `dir` if needed and checks that files can be created in it (by
/// creating and removing a temporary file), so that a command refuses an unusable output
/// folder before its work rather than after.
pub fn prepare_output_dir(dir: &Path) -> Result<(), String> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    if let Err(e) = std::fs::create_dir_all(dir) {
        // Name the culprit when a file stands where a folder is needed.
        let blocker = dir
            .ancestors()
            .find(|a| !a.as_os_str().is_empty() && a.exists())
            .filter(|a| !a.is_dir());
        return Err(match blocker {
            Some(b) => format!(
                "cannot create the output folder {}: {} is a file, not a folder",
                dir.display(),
                b.display()
            ),
            None => format!("cannot create the output folder {}: {e}", dir.display()),
        });
    }
    tempfile::Builder::new()
        .prefix(".matfit-probe-")
        .tempfile_in(dir)
        .map(drop)
        .map_err(|e| format!("cannot write into the output folder {}: {e}", dir.display()))
}

/// Checks that the output file `path` can be written: its folder exists and accepts new files,
/// and `path` is not a folder.
pub fn check_output_file(path: &Path) -> Result<(), String> {
    if path.is_dir() {
        return Err(format!("cannot write {}: it is a folder", path.display()));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if dir.exists() && !dir.is_dir() {
        return Err(format!(
            "cannot write {}: {} is a file, not a folder",
            path.display(),
            dir.display()
        ));
    }
    if !dir.is_dir() {
        return Err(format!(
            "cannot write {}: the folder {} does not exist",
            path.display(),
            dir.display()
        ));
    }
    tempfile::Builder::new()
        .prefix(".matfit-probe-")
        .tempfile_in(dir)
        .map(drop)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    #[test]
    fn writes_and_replaces() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.txt");
        super::write_atomic(&p, b"one").unwrap();
        super::write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(
            std::fs::read_dir(d.path()).unwrap().count(),
            1,
            "no temporary left behind"
        );
    }

    #[cfg(unix)]
    #[test]
    fn outputs_get_the_permissions_of_a_plainly_created_file() {
        use std::os::unix::fs::PermissionsExt;
        let d = tempfile::tempdir().unwrap();
        let (a, b) = (d.path().join("atomic"), d.path().join("plain"));
        super::write_atomic(&a, b"x").unwrap();
        std::fs::write(&b, b"x").unwrap();
        let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode();
        assert_eq!(mode(&a), mode(&b));
    }

    #[test]
    fn unusable_output_places_are_refused_with_the_culprit_named() {
        let d = tempfile::tempdir().unwrap();
        let file = d.path().join("f");
        std::fs::write(&file, b"x").unwrap();
        let e = super::prepare_output_dir(&file.join("out")).unwrap_err();
        assert!(e.contains("is a file, not a folder"), "{e}");
        let e = super::check_output_file(&file.join("x.exr")).unwrap_err();
        assert!(e.contains("is a file, not a folder"), "{e}");
        let e = super::check_output_file(&d.path().join("no/x.png")).unwrap_err();
        assert!(e.contains("does not exist"), "{e}");
        let e = super::check_output_file(d.path()).unwrap_err();
        assert!(e.contains("it is a folder"), "{e}");
        super::prepare_output_dir(&d.path().join("a/b")).unwrap();
        super::check_output_file(&d.path().join("a/b/x.png")).unwrap();
        assert_eq!(std::fs::read_dir(d.path().join("a/b")).unwrap().count(), 0);
    }
}
