//! `matfit hdr`: exposure brackets → one linear image for `recover`, with the response curve
//! given or recovered from the brackets (`photo::hdr`, `photo::calibrate`).

use super::*;
use crate::outln;
use anyhow::{bail, Result};
use matfit::io::atomic::{check_output_file, write_atomic};
use matfit::photo::brackets::load_brackets;
use matfit::photo::calibrate::recover_response;
use matfit::photo::hdr::merge;
use matfit::photo::Response;
use std::path::PathBuf;
use std::sync::Arc;

/// The response of `hdr`: known, or recovered from the brackets.
#[derive(Clone, Debug)]
pub enum HdrResponse {
    Recover,
    Known(Response),
}

/// `recover`, or what `Response::parse` reads.
pub fn parse_response(s: &str) -> Result<HdrResponse, String> {
    if s.trim().eq_ignore_ascii_case("recover") {
        Ok(HdrResponse::Recover)
    } else {
        Response::parse(s)
            .map(HdrResponse::Known)
            .map_err(|e| format!("{e}, or recover"))
    }
}

/// The exposure times of `--times`, as one value for clap.
#[derive(Clone, Debug)]
pub struct Times(pub Vec<f32>);

pub fn parse_times(s: &str) -> Result<Times, String> {
    matfit::photo::brackets::parse_times(s).map(Times)
}

pub struct HdrArgs {
    pub images: Vec<PathBuf>,
    pub times: Vec<f32>,
    pub output: PathBuf,
    pub response: HdrResponse,
    pub response_out: Option<PathBuf>,
}

pub fn run(a: &HdrArgs) -> Result<()> {
    let ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if !["exr", "pfm", "hdr"].contains(&ext.as_str()) {
        bail!(
            "{}: the merged image must be linear: .exr, .pfm or .hdr",
            a.output.display()
        );
    }
    check_output_file(&a.output).map_err(anyhow::Error::msg)?;
    if let Some(p) = &a.response_out {
        if matches!(a.response, HdrResponse::Known(_)) {
            bail!("--response-out writes a recovered response: use it with --response recover");
        }
        check_output_file(p).map_err(anyhow::Error::msg)?;
    }
    let b = load_brackets(&a.images, &a.times).map_err(anyhow::Error::msg)?;
    let response = match &a.response {
        HdrResponse::Known(r) => r.clone(),
        HdrResponse::Recover => {
            let bins = if b.bits <= 8 { 256 } else { 1024 };
            let r = recover_response(&b, bins).map_err(anyhow::Error::msg)?;
            outln!(
                "response recovered from the brackets ({bins} codes, rms misfit {:.3} ln units); \
                 scaled to 1 at the middle code: calibrate the exposure in recover \
                 (--grey-card or --exposure-from-lights)",
                r.rms
            );
            if let Some(p) = &a.response_out {
                write_atomic(p, r.table.to_text().as_bytes())
                    .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", p.display()))?;
                outln!("wrote {} (use it as --response table:{0})", p.display());
            }
            Response::Table(Arc::new(r.table))
        }
    };
    let m = merge(&b, &response);
    let n = b.width() * b.height();
    if m.unmeasured == n {
        bail!(
            "no pixel has a well-exposed code in any of the {} images (all clipped or black): \
             check the exposure times and the images",
            b.images.len()
        );
    }
    for (k, what, got) in [
        (
            m.clipped_everywhere,
            "clipped in every exposure",
            "the shortest exposure's value, a lower bound",
        ),
        (
            m.black_everywhere,
            "black in every exposure",
            "the longest exposure's value, an upper bound",
        ),
    ] {
        if k > 0 {
            super::out::warn(format!(
                "{k} of {n} pixels ({:.2}%) have a channel {what}: no well-exposed code, they \
                 got {got}; add a {} exposure or mask them in recover (--ignore-mask)",
                100.0 * k as f64 / n as f64,
                if what.starts_with("clipped") {
                    "shorter"
                } else {
                    "longer"
                }
            ));
        }
    }
    m.image.write(&a.output).map_err(anyhow::Error::msg)?;
    outln!(
        "wrote {} ({}×{}, {} {}-bit exposures, response {})",
        a.output.display(),
        b.width(),
        b.height(),
        b.images.len(),
        b.bits,
        match &a.response {
            HdrResponse::Recover => "recovered".to_string(),
            HdrResponse::Known(r) => r.name(),
        }
    );
    Ok(())
}

/// The arguments of `matfit hdr` (see `Command::Hdr`).
#[derive(clap::Args)]
pub struct HdrCli {
    /// The brackets, in any order, all of one size and bit depth.
    #[arg(required = true, num_args = 2.., value_name = "IMAGE")]
    images: Vec<PathBuf>,
    /// Exposure time of each image, in the images' order, fractions or decimals; required
    /// (e.g. 1/60,1/15,0.25). Only their ratios matter to the merge.
    #[arg(long, value_name = "T1,T2,...", value_parser = hdr::parse_times)]
    times: hdr::Times,
    /// Output image: .exr, .pfm or .hdr (linear).
    #[arg(short, long)]
    output: PathBuf,
    /// Response curve of the brackets: recover (from the brackets themselves, Debevec &
    /// Malik's least squares on a smooth curve), srgb, linear, gamma:G (linear = code^G) or
    /// table:FILE.
    #[arg(long, value_name = "R", default_value = "recover", value_parser = hdr::parse_response)]
    response: hdr::HdrResponse,
    /// Write the recovered response here, as a table that --response table:FILE reads
    /// (linear values, one row per code) [default: not written].
    #[arg(long, value_name = "FILE")]
    response_out: Option<PathBuf>,
}

/// Runs `matfit hdr`.
pub fn command(args: HdrCli) -> Result<()> {
    let HdrCli {
        images,
        times,
        output,
        response,
        response_out,
    } = args;
    hdr::run(&hdr::HdrArgs {
        images,
        times: times.0,
        output,
        response,
        response_out,
    })
}
