//! Camera response curves: how the integer code values of an 8- or 16-bit photo (PNG, JPEG) map
//! to linear radiance. Float photos (EXR, HDR, PFM) are linear already and never go through one.
//!
//! On the command line a response is written `srgb` (the default), `linear`, `gamma:G`
//! (linear = v^G for the code v scaled to [0, 1]; `gamma:2.2` is the classic video curve) or
//! `table:FILE`.
//!
//! # Table files
//!
//! A text file, one row per code value, `#` starting a comment, blank lines ignored. Rows have
//! one of four shapes, all rows of a file the same:
//!
//! | columns | meaning |
//! |---|---|
//! | `Y` | linear value of code *i* (the row's index), grey |
//! | `R G B` | linear value of code *i* per channel |
//! | `CODE Y` | linear value of the integer code `CODE`, grey |
//! | `CODE R G B` | linear value of `CODE` per channel |
//!
//! Without a code column the file has one row per code: 256 rows for 8-bit photos, 65536 for
//! 16-bit ones (another count N ≥ 2 is read as N evenly spaced codes over the full range). With a
//! code column the codes must increase strictly; they are integers of an 8-bit range if the
//! largest is ≤ 255, of a 16-bit range otherwise, and values between listed codes are
//! interpolated linearly. The values must be finite, ≥ 0, non-decreasing and not all equal;
//! their scale does not matter beyond the exposure factor (it multiplies every pixel alike).
//!
//! The columns are *linear* values. An HDR calibration that gives the log response
//! g(Z) = ln E (Debevec & Malik 1997, `mkhdr`, OpenCV's `CalibrateDebevec`, whose
//! `createCalibrateDebevec` output is already linear) must be exponentiated first.

use crate::io::image::{srgb_decode, srgb_encode};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How integer-coded photos are turned into linear values.
#[derive(Clone, Debug, PartialEq, Default)]
pub enum Response {
    /// The sRGB curve (the default for 8/16-bit files).
    #[default]
    Srgb,
    /// v^g.
    Gamma(f32),
    /// Already linear.
    Linear,
    /// A measured curve from a table file (see the module documentation).
    Table(Arc<ResponseTable>),
}

/// A tabulated response: knots (normalised code in [0, 1], linear RGB), codes increasing.
#[derive(Clone, Debug, PartialEq)]
pub struct ResponseTable {
    pub path: PathBuf,
    pub codes: Vec<f32>,
    pub values: Vec<[f32; 3]>,
}

impl Response {
    /// Parses `srgb`, `linear`, `gamma:G` or `table:FILE` (the command-line form).
    pub fn parse(s: &str) -> Result<Response, String> {
        let (kind, arg) = match s.split_once(':') {
            Some((k, a)) => (k.trim().to_ascii_lowercase(), Some(a.trim())),
            None => (s.trim().to_ascii_lowercase(), None),
        };
        match (kind.as_str(), arg) {
            ("srgb", None) => Ok(Response::Srgb),
            ("linear", None) => Ok(Response::Linear),
            ("gamma", Some(g)) => {
                let g: f32 = g
                    .parse()
                    .map_err(|_| format!("gamma:{g}: the exponent is not a number"))?;
                if !(g > 0.0 && g.is_finite()) {
                    return Err(format!("gamma:{g}: the exponent must be positive"));
                }
                Ok(Response::Gamma(g))
            }
            ("table", Some(f)) if !f.is_empty() => Ok(Response::Table(Arc::new(
                ResponseTable::load(Path::new(f))?,
            ))),
            _ => Err(format!(
                "unknown response '{s}' (use srgb, linear, gamma:G or table:FILE)"
            )),
        }
    }

    /// Linear value of channel `ch` (0, 1, 2) for the code value `v` scaled to [0, 1].
    pub fn linearize_channel(&self, v: f32, ch: usize) -> f32 {
        match self {
            Response::Srgb => srgb_decode(v),
            Response::Gamma(g) => v.max(0.0).powf(*g),
            Response::Linear => v,
            Response::Table(t) => t.eval(v, ch),
        }
    }

    /// Linear value of a grey code value `v` in [0, 1] (channel 0 of a table).
    pub fn linearize(&self, v: f32) -> f32 {
        self.linearize_channel(v, 0)
    }

    /// The inverse: code value in [0, 1] of a linear value (clipped to the curve's range). Used
    /// to make 8-bit test photos and to draw previews in the photo's own encoding.
    pub fn encode_channel(&self, x: f32, ch: usize) -> f32 {
        match self {
            Response::Srgb => srgb_encode(x),
            Response::Gamma(g) => x.clamp(0.0, 1.0).powf(1.0 / g),
            Response::Linear => x.clamp(0.0, 1.0),
            Response::Table(t) => t.invert(x, ch),
        }
    }

    /// A short name for messages and logs.
    pub fn name(&self) -> String {
        match self {
            Response::Srgb => "srgb".into(),
            Response::Linear => "linear".into(),
            Response::Gamma(g) => format!("gamma:{g}"),
            Response::Table(t) => format!("table:{}", t.path.display()),
        }
    }
}

impl ResponseTable {
    /// Reads a table file (format in the module documentation).
    pub fn load(path: &Path) -> Result<ResponseTable, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("{}: cannot read the response table: {e}", path.display()))?;
        Self::parse(&text, path)
    }

    /// Parses table text as if it were the file at `path`.
    #[allow(clippy::needless_range_loop)]
    pub fn parse(text: &str, path: &Path) -> Result<ResponseTable, String> {
        let err = |line: usize, m: String| format!("{}:{line}: {m}", path.display());
        let mut rows: Vec<(usize, Vec<f64>)> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line_no = i + 1;
            let body = line.split('#').next().unwrap_or("").trim();
            if body.is_empty() {
                continue;
            }
            let nums: Result<Vec<f64>, _> = body
                .split(|c: char| c.is_whitespace() || c == ',')
                .filter(|t| !t.is_empty())
                .map(|t| t.parse::<f64>())
                .collect();
            let nums = nums.map_err(|_| err(line_no, format!("'{body}' is not numbers")))?;
            if let Some((_, first)) = rows.first() {
                if first.len() != nums.len() {
                    return Err(err(
                        line_no,
                        format!(
                            "{} columns, but the first row has {}",
                            nums.len(),
                            first.len()
                        ),
                    ));
                }
            }
            if !(1..=4).contains(&nums.len()) {
                return Err(err(
                    line_no,
                    format!("{} columns (expected 1 to 4)", nums.len()),
                ));
            }
            rows.push((line_no, nums));
        }
        if rows.len() < 2 {
            return Err(format!(
                "{}: a response table needs at least 2 rows, found {}",
                path.display(),
                rows.len()
            ));
        }
        let cols = rows[0].1.len();
        let has_code = cols == 2 || cols == 4;
        let n = rows.len();
        let max_code = if has_code {
            let m = rows.iter().map(|r| r.1[0]).fold(f64::MIN, f64::max);
            if m <= 255.0 {
                255.0
            } else {
                65535.0
            }
        } else {
            (n - 1) as f64
        };
        let mut codes = Vec::with_capacity(n);
        let mut values = Vec::with_capacity(n);
        for (k, (line, r)) in rows.iter().enumerate() {
            let (code, vals) = if has_code {
                (r[0], &r[1..])
            } else {
                (k as f64, &r[..])
            };
            if has_code && (code < 0.0 || code.fract() != 0.0 || code > 65535.0) {
                return Err(err(
                    *line,
                    format!("code {code} is not an integer in 0..=65535"),
                ));
            }
            let v = if vals.len() == 1 {
                [vals[0]; 3]
            } else {
                [vals[0], vals[1], vals[2]]
            };
            if v.iter().any(|x| !x.is_finite() || *x < 0.0) {
                return Err(err(
                    *line,
                    "linear values must be finite and ≥ 0 (a log response must be exponentiated)"
                        .into(),
                ));
            }
            codes.push((code / max_code) as f32);
            values.push(v.map(|x| x as f32));
        }
        for k in 1..n {
            if codes[k] <= codes[k - 1] {
                return Err(err(rows[k].0, "codes must increase strictly".into()));
            }
            for ch in 0..3 {
                if values[k][ch] < values[k - 1][ch] {
                    return Err(err(
                        rows[k].0,
                        "the response must be non-decreasing (a brighter code cannot mean less light)"
                            .into(),
                    ));
                }
            }
        }
        for ch in 0..3 {
            if values[n - 1][ch] <= values[0][ch] {
                return Err(format!(
                    "{}: the response is flat in channel {ch}",
                    path.display()
                ));
            }
        }
        Ok(ResponseTable {
            path: path.to_owned(),
            codes,
            values,
        })
    }

    /// The table in its file format: one row per knot, the knots evenly spaced over the code
    /// range (as `matfit hdr` recovers them), grey or R G B. `parse` reads it back.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "# matfit response table: linear value of {} evenly spaced codes, darkest first\n",
            self.codes.len()
        );
        // One column when every row is grey (the parser wants the same count on every row).
        let grey = self.values.iter().all(|v| v[0] == v[1] && v[1] == v[2]);
        for v in &self.values {
            if grey {
                s.push_str(&format!("{:e}\n", v[0]));
            } else {
                s.push_str(&format!("{:e} {:e} {:e}\n", v[0], v[1], v[2]));
            }
        }
        s
    }

    /// Linear value of channel `ch` at normalised code `v`, interpolated linearly between knots
    /// and held constant outside them.
    pub fn eval(&self, v: f32, ch: usize) -> f32 {
        let c = &self.codes;
        if v <= c[0] {
            return self.values[0][ch];
        }
        let n = c.len();
        if v >= c[n - 1] {
            return self.values[n - 1][ch];
        }
        let k = c.partition_point(|&x| x <= v).clamp(1, n - 1);
        let t = (v - c[k - 1]) / (c[k] - c[k - 1]);
        self.values[k - 1][ch] * (1.0 - t) + self.values[k][ch] * t
    }

    /// The normalised code whose linear value is `x` (inverse of [`eval`](Self::eval)).
    pub fn invert(&self, x: f32, ch: usize) -> f32 {
        let n = self.codes.len();
        let val = |k: usize| self.values[k][ch];
        if x <= val(0) {
            return self.codes[0];
        }
        if x >= val(n - 1) {
            return self.codes[n - 1];
        }
        let k = (1..n).find(|&k| val(k) >= x).unwrap_or(n - 1);
        let (a, b) = (val(k - 1), val(k));
        let t = if b > a { (x - a) / (b - a) } else { 0.0 };
        self.codes[k - 1] + t * (self.codes[k] - self.codes[k - 1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quantise(v: f32, bits: u32) -> f32 {
        let m = ((1u32 << bits) - 1) as f32;
        (v * m).round() / m
    }

    /// Encoding then decoding an 8-bit code gives back the linear value within one code step.
    fn round_trip(r: &Response, tol_rel: f32) {
        for i in 0..=100 {
            let x = i as f32 / 100.0;
            let code = quantise(r.encode_channel(x, 1), 8);
            let back = r.linearize_channel(code, 1);
            // One code step of slope dx/dv, plus a small absolute floor near black.
            assert!(
                (back - x).abs() <= tol_rel * x + 2e-3,
                "{}: {x} -> {code} -> {back}",
                r.name()
            );
        }
    }

    #[test]
    fn srgb_gamma_linear_round_trip() {
        round_trip(&Response::Srgb, 0.02);
        round_trip(&Response::Gamma(2.2), 0.02);
        round_trip(&Response::Linear, 0.0);
        assert_eq!(Response::parse("gamma:2.2").unwrap(), Response::Gamma(2.2));
        assert_eq!(Response::parse("SRGB").unwrap(), Response::Srgb);
        assert!((Response::Gamma(2.2).linearize(0.5) - 0.5f32.powf(2.2)).abs() < 1e-6);
        for bad in ["gamma:", "gamma:-1", "gamma:x", "tabel:x", "table:"] {
            assert!(Response::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn table_files_all_shapes() {
        let d = tempfile::tempdir().unwrap();
        // 256 rows, one column: the sRGB curve tabulated must decode like the sRGB curve.
        let text: String = (0..256)
            .map(|i| format!("{}\n", srgb_decode(i as f32 / 255.0)))
            .collect();
        let p = d.path().join("srgb.txt");
        std::fs::write(&p, format!("# sRGB\n{text}")).unwrap();
        let t = Response::parse(&format!("table:{}", p.display())).unwrap();
        for i in 0..256 {
            let v = i as f32 / 255.0;
            assert!((t.linearize(v) - srgb_decode(v)).abs() < 1e-6);
        }
        round_trip(&t, 0.02);
        // Two columns, sparse codes, interpolated; four columns with per-channel curves.
        let t2 = ResponseTable::parse("0 0\n128 0.25\n255 1.0\n", Path::new("a.txt")).unwrap();
        assert!((t2.eval(64.0 / 255.0, 0) - 0.125).abs() < 1e-6);
        assert!((t2.eval(1.0, 2) - 1.0).abs() < 1e-6);
        let t4 = ResponseTable::parse("0 0 0 0\n255 1 2 4\n", Path::new("a.txt")).unwrap();
        assert!((t4.eval(0.5, 2) - 2.0).abs() < 1e-6);
        assert!((t4.invert(1.0, 2) - 0.25).abs() < 1e-6);
        // A 16-bit table (largest code > 255).
        let t16 = ResponseTable::parse("0 0\n65535 1\n", Path::new("a.txt")).unwrap();
        assert!((t16.eval(0.5, 0) - 0.5).abs() < 1e-6);
        // 65536 rows without codes: one per 16-bit code.
        let big: String = (0..65536)
            .map(|i| format!("{}\n", i as f32 / 65535.0))
            .collect();
        let tb = ResponseTable::parse(&big, Path::new("b.txt")).unwrap();
        assert!((tb.eval(quantise(0.3, 16), 1) - quantise(0.3, 16)).abs() < 1e-6);
        // Bad tables: each names the file and the line.
        for (text, needle) in [
            (
                "0\n0.5\n0.4\n",
                "a.txt:3: the response must be non-decreasing",
            ),
            ("0\nx\n", "a.txt:2: 'x' is not numbers"),
            ("0\n", "at least 2 rows"),
            ("0 0\n1\n", "a.txt:2: 1 columns"),
            ("0\n-1\n", "a.txt:2: linear values must be finite"),
            ("0\n0\n", "flat"),
            ("5 0\n3 1\n", "a.txt:2: codes must increase"),
        ] {
            let e = ResponseTable::parse(text, Path::new("a.txt")).unwrap_err();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
        assert!(Response::parse("table:/nonexistent/r.txt")
            .unwrap_err()
            .contains("/nonexistent/r.txt"));
    }
}
