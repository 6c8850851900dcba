//! `matfit import`: another renderer's scene read into a matfit scene file.

use super::*;

/// The arguments of `matfit import` (see `Command::Import`).
#[derive(clap::Args)]
pub struct ImportCli {
    /// Source renderer.
    format: ImportFormatArg,
    /// The scene file to read (Mitsuba 3 XML).
    input: PathBuf,
    /// Output scene file (.toml).
    #[arg(short, long)]
    output: PathBuf,
    /// Set a scene parameter ($NAME in the XML), overriding its <default> (e.g. -D spp=256;
    /// repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_param)]
    define: Vec<(String, String)>,
}

/// Runs `matfit import`.
pub fn command(args: ImportCli) -> Result<()> {
    let ImportCli {
        format,
        input,
        output,
        define,
    } = args;
    let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("");
    if !ext.eq_ignore_ascii_case("toml") {
        bail!(
            "{}: the output scene file must end in .toml",
            output.display()
        );
    }
    check_output_file(&output).map_err(anyhow::Error::msg)?;
    let report = match format {
        ImportFormatArg::Mitsuba => {
            matfit::import::mitsuba::import(&input, &output, &define).map_err(anyhow::Error::msg)?
        }
    };
    let folder = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    report.write_files(&folder).map_err(anyhow::Error::msg)?;
    // The written file must be a scene that loads (its meshes found from its folder).
    matfit::scene::load::parse_scene(&report.toml, &output)
        .map_err(|e| anyhow::anyhow!("the imported scene does not load: {e}"))?;
    matfit::io::atomic::write_atomic(&output, report.toml.as_bytes())
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", output.display()))?;
    for w in &report.warnings {
        out::warn(w.clone());
    }
    outln!(
        "wrote {} ({} warning{}){}",
        output.display(),
        report.warnings.len(),
        if report.warnings.len() == 1 { "" } else { "s" },
        match report.textures.len() {
            0 => String::new(),
            n => format!(
                " and {n} texture{} turned to matfit's texture coordinates in {}",
                if n == 1 { "" } else { "s" },
                folder.join("textures").display()
            ),
        }
    );
    Ok(())
}
