//! Portable float map (PFM) codec: the `image` crate does not read or write it.
//! Header "PF\n<w> <h>\n<scale>\n", negative scale = little-endian; rows bottom to top.

use crate::math::Rgb;

/// Encodes RGB rows (top row first) as a little-endian colour PFM.
pub fn encode(width: usize, height: usize, data: &[Rgb]) -> Vec<u8> {
    let mut out = format!("PF\n{width} {height}\n-1.0\n").into_bytes();
    out.reserve(width * height * 12);
    for y in (0..height).rev() {
        for p in &data[y * width..(y + 1) * width] {
            for c in [p.x, p.y, p.z] {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    out
}

/// Decodes a colour ("PF") or grey ("Pf") PFM into RGB rows, top row first.
pub fn decode(bytes: &[u8]) -> Result<(usize, usize, Vec<Rgb>), String> {
    // Three whitespace-separated header tokens after the magic, then one whitespace byte.
    let mut pos = 0;
    let mut token = || -> Result<String, String> {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err("truncated PFM header".into());
        }
        Ok(String::from_utf8_lossy(&bytes[start..pos]).into_owned())
    };
    let magic = token()?;
    let channels = match magic.as_str() {
        "PF" => 3,
        "Pf" => 1,
        _ => return Err("not a PFM file (expected 'PF' or 'Pf')".into()),
    };
    let w: usize = token()?.parse().map_err(|_| "bad PFM width")?;
    let h: usize = token()?.parse().map_err(|_| "bad PFM height")?;
    let scale: f32 = token()?.parse().map_err(|_| "bad PFM scale")?;
    pos += 1;
    if w == 0 || h == 0 {
        return Err(format!("PFM image is {w}×{h}"));
    }
    if !scale.is_finite() || scale == 0.0 {
        return Err(format!("bad PFM scale {scale} (must be a non-zero number)"));
    }
    let pixels = w.checked_mul(h).ok_or("PFM dimensions overflow")?;
    if pixels > super::MAX_PIXELS {
        return Err(format!(
            "the image is {w}×{h}, more than matfit's limit of {} megapixels; downsample it \
             (and scale the camera: width, height and fx, fy, cx, cy)",
            super::MAX_PIXELS >> 20
        ));
    }
    let need = pixels * channels * 4;
    let have = bytes.len().saturating_sub(pos);
    if have < need {
        return Err(format!("truncated PFM data: {have} of {need} bytes"));
    }
    let le = scale < 0.0;
    let f = |i: usize| {
        let b: [u8; 4] = bytes[pos + 4 * i..pos + 4 * i + 4].try_into().unwrap();
        if le {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let mut data = vec![Rgb::ZERO; w * h];
    for y in 0..h {
        for x in 0..w {
            let src = ((h - 1 - y) * w + x) * channels;
            data[y * w + x] = if channels == 3 {
                Rgb::new(f(src), f(src + 1), f(src + 2))
            } else {
                Rgb::splat(f(src))
            };
        }
    }
    Ok((w, h, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        let data: Vec<Rgb> = (0..6)
            .map(|i| Rgb::new(i as f32, -0.5, 1e-7 * i as f32))
            .collect();
        let bytes = encode(3, 2, &data);
        let (w, h, back) = decode(&bytes).unwrap();
        assert_eq!((w, h), (3, 2));
        assert_eq!(back, data);
        assert!(decode(&bytes[..bytes.len() - 1])
            .unwrap_err()
            .contains("truncated"));
        assert!(decode(b"P6\n1 1\n255\n").is_err());
    }
}
