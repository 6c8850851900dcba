//! The report's convergence plots: per group, ε of each global iteration's fit and its noise
//! floor, with the level changes marked, read back from `log.jsonl` (the run's own record, so a
//! resumed run plots all of it). Drawn as SVG by `plotters`.

use plotters::prelude::*;
use std::collections::BTreeMap;

/// One group's history in the log.
#[derive(Debug, Default, PartialEq)]
pub struct History {
    /// (iteration, ε, noise floor) of each fit at the group's level.
    pub fits: Vec<(u32, f32, f32)>,
    /// (iteration, the level moved or demoted to).
    pub moves: Vec<(u32, String)>,
    /// The iteration it was confirmed or decided at, and its level.
    pub decided: Option<(u32, String)>,
}

/// Every group's history, in the order groups first appear in `log` (JSON lines as
/// `recover` writes them; lines that are not its events are skipped).
pub fn histories(log: &str) -> Vec<(String, History)> {
    let mut order = Vec::new();
    let mut by_group: BTreeMap<String, History> = BTreeMap::new();
    for line in log.lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let (Some(group), Some(event), Some(it)) = (
            v["group"].as_str(),
            v["event"].as_str(),
            v["iteration"].as_u64(),
        ) else {
            continue;
        };
        if !by_group.contains_key(group) {
            order.push(group.to_string());
        }
        let h = by_group.entry(group.to_string()).or_default();
        let it = it as u32;
        let num = |k: &str| v[k].as_f64().map(|x| x as f32);
        match event {
            "fit" => {
                if let (Some(e), Some(n)) = (num("error"), num("noise_floor")) {
                    h.fits.push((it, e, n));
                }
            }
            "moved" | "demoted" => {
                if let Some(to) = v["to"].as_str() {
                    h.moves.push((it, to.to_string()));
                }
            }
            "confirmed" | "decided" => {
                if let Some(level) = v["level"].as_str() {
                    h.decided.get_or_insert((it, level.to_string()));
                }
            }
            _ => {}
        }
    }
    order
        .into_iter()
        .map(|g| {
            let h = by_group.remove(&g).unwrap_or_default();
            (g, h)
        })
        .collect()
}

/// The SVG plot of one group's history: ε per iteration (log scale), the noise floor, a red
/// line where the level changed (labelled with the new level), a green one where it was
/// confirmed. None for a group with no fit.
pub fn convergence_svg(group: &str, h: &History) -> Option<String> {
    let finite = |x: &f32| x.is_finite() && *x > 0.0;
    let values: Vec<f32> = h
        .fits
        .iter()
        .flat_map(|f| [f.1, f.2])
        .filter(finite)
        .collect();
    if values.is_empty() {
        return None;
    }
    let lo = values.iter().copied().fold(f32::INFINITY, f32::min) as f64 * 0.7;
    let hi = values.iter().copied().fold(0.0f32, f32::max) as f64 * 1.6;
    let last = h.fits.iter().map(|f| f.0).max().unwrap_or(0).max(1);
    let mut svg = String::new();
    let drawn = (|| -> Result<(), Box<dyn std::error::Error + '_>> {
        let root = SVGBackend::with_string(&mut svg, (440, 230)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(group, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(52)
            .build_cartesian_2d(
                0u32..last,
                (lo..hi).log_scale().with_key_points(log_ticks(lo, hi)),
            )?;
        chart
            .configure_mesh()
            .x_desc("global iteration")
            .y_desc("ε")
            .y_label_formatter(&|v| percent(*v))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        let grey = RGBColor(140, 140, 140);
        chart
            .draw_series(LineSeries::new(
                h.fits
                    .iter()
                    .filter(|f| finite(&f.2))
                    .map(|f| (f.0, f.2 as f64)),
                grey.stroke_width(1),
            ))?
            .label("noise floor")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], grey));
        chart
            .draw_series(LineSeries::new(
                h.fits
                    .iter()
                    .filter(|f| finite(&f.1))
                    .map(|f| (f.0, f.1 as f64)),
                BLACK.stroke_width(2),
            ))?
            .label("ε of the fit")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], BLACK.stroke_width(2)));
        for (it, to) in &h.moves {
            chart.draw_series(LineSeries::new([(*it, lo), (*it, hi)], RED.stroke_width(1)))?;
            chart.draw_series([Text::new(
                format!("→ {to}"),
                (*it, hi * 0.8),
                ("sans-serif", 11).into_font().color(&RED),
            )])?;
        }
        if let Some((it, level)) = &h.decided {
            let green = RGBColor(0, 140, 60);
            chart.draw_series(LineSeries::new(
                [(*it, lo), (*it, hi)],
                green.stroke_width(1),
            ))?;
            chart.draw_series([Text::new(
                format!("confirmed {level}"),
                (*it, lo * 1.3),
                ("sans-serif", 11).into_font().color(&green),
            )])?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .border_style(RGBColor(200, 200, 200))
            .background_style(WHITE.mix(0.85))
            .draw()?;
        root.present()?;
        Ok(())
    })();
    drawn.ok()?;
    Some(svg)
}

/// Tick values for a log axis over [lo, hi]: 1, 2 and 5 times the powers of ten inside it, or
/// (a range spanning less than that) every digit's, or else five evenly spaced in log rounded
/// to two digits. plotters' own log ticks are the powers of ten alone, so a range that spans
/// none had no label at all.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo) {
        return vec![];
    }
    let within = |mantissas: &[f64]| -> Vec<f64> {
        let (a, b) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        (a..=b)
            .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    for mantissas in [
        &[1.0, 2.0, 5.0][..],
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ] {
        let t = within(mantissas);
        if t.len() >= 3 {
            return t;
        }
    }
    let mut t: Vec<f64> = (0..=5)
        .map(|i| {
            let v = lo * (hi / lo).powf(i as f64 / 5.0);
            let scale = 10f64.powi(v.log10().floor() as i32 - 1);
            (v / scale).round() * scale
        })
        .filter(|v| (lo..=hi).contains(v))
        .collect();
    t.dedup();
    t
}

/// A fraction as a percentage with two significant digits at least.
fn percent(v: f64) -> String {
    let p = 100.0 * v;
    let decimals = if p > 0.0 {
        (1 - p.log10().floor() as i32).max(0)
    } else {
        2
    };
    format!("{p:.*}%", decimals as usize)
}

#[cfg(test)]
mod tests {
    /// A range that spans no power of ten still gets labelled ticks.
    #[test]
    fn log_ticks_label_a_range_without_a_power_of_ten() {
        for (lo, hi) in [(0.013, 0.019), (0.02, 0.09), (0.0011, 0.35), (0.5, 0.52)] {
            let t = super::log_ticks(lo, hi);
            assert!(t.len() >= 2, "{lo}..{hi}: {t:?}");
            assert!(t.iter().all(|v| (lo..=hi).contains(v)), "{lo}..{hi}: {t:?}");
        }
        assert_eq!(super::percent(0.0153), "1.5%");
        assert_eq!(super::percent(0.00042), "0.042%");
        assert_eq!(super::percent(0.25), "25%");
    }

    use super::*;

    const LOG: &str = r#"{"iteration":0,"group":"floor","event":"fit","level":"diffuse","error":0.2,"noise_floor":0.01}
{"iteration":1,"group":"floor","event":"fit","level":"diffuse","error":0.1,"noise_floor":0.01}
{"iteration":1,"group":"wall","event":"fit","level":"diffuse","error":0.05,"noise_floor":0.02}
{"iteration":1,"group":"floor","event":"moved","from":"diffuse","to":"isotropic"}
{"iteration":2,"group":"floor","event":"fit","level":"isotropic","error":0.02,"noise_floor":0.01}
{"iteration":2,"group":"floor","event":"confirmed","level":"isotropic","error":0.02,"below_threshold":true}
not json
"#;

    #[test]
    fn the_log_is_read_back_per_group_and_plotted() {
        let h = histories(LOG);
        let names: Vec<&str> = h.iter().map(|(g, _)| g.as_str()).collect();
        assert_eq!(names, ["floor", "wall"]);
        let floor = &h[0].1;
        assert_eq!(
            floor.fits,
            [(0, 0.2, 0.01), (1, 0.1, 0.01), (2, 0.02, 0.01)]
        );
        assert_eq!(floor.moves, [(1, "isotropic".to_string())]);
        assert_eq!(floor.decided, Some((2, "isotropic".to_string())));
        let svg = convergence_svg("floor", floor).unwrap();
        assert!(svg.starts_with("<svg"), "{svg}");
        // The two series, the level change's label and the confirmation's.
        assert!(svg.matches("<polyline").count() >= 2, "{svg}");
        assert!(svg.contains("→ isotropic") && svg.contains("confirmed isotropic"));
        assert!(convergence_svg("none", &History::default()).is_none());
    }
}
